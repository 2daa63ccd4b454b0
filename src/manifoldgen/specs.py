"""Sampler specifications, as the CLI and the benchmarks name them.

``uniform`` (rejection in the joint limits), ``project`` (uniform seeds projected),
``pg:DATASET.npz`` (the paper's precomputed-graph baseline: rows of a dataset) or
``MODEL:DIR`` (a trained model directory, e.g. ``cvae:runs/cvae``; any registered model
name). Options follow after commas: ``cvae:runs/cvae,refine=0,batch=2048``; model samples
get ``MODEL_REFINE`` projection iterations unless ``refine`` says otherwise (``refine=0``:
raw model samples, the paper's setting).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from manifoldgen.collision import CollisionChecker
from manifoldgen.data import Dataset
from manifoldgen.errors import ManifoldgenError
from manifoldgen.sampling import DatasetSampler, ProjectionSampler, Sampler, UniformSampler
from manifoldgen.tasks import Task

SPEC_HELP = "uniform, project, pg:DATASET.npz, or MODEL:DIR (e.g. cvae:runs/cvae; options: ,refine=N,batch=B)"
OPTIONS = {"refine": int, "batch": int}
MODEL_REFINE = 2  # Algorithm 1's refinement: samples on the manifold connect by straight segments twice as often


def parse_spec(spec: str) -> tuple[str, str, dict[str, int]]:
    """``'cvae:dir,refine=2'`` -> ``('cvae', 'dir', {'refine': 2})``."""
    head, *options = spec.strip().split(",")
    name, _, arg = head.partition(":")
    parsed = {}
    for option in options:
        key, eq, value = option.partition("=")
        if key not in OPTIONS or not eq:
            raise ManifoldgenError(f"bad sampler option '{option}' in '{spec}'; options: "
                                   f"{', '.join(f'{k}=N' for k in OPTIONS)}")
        try:
            parsed[key] = OPTIONS[key](value)
        except ValueError as exc:
            raise ManifoldgenError(f"sampler option {key} must be an integer, got '{value}'") from exc
    return name, arg, parsed


def make_sampler(spec: str, task: Task, y: np.ndarray, checker: CollisionChecker | None, seed: int) -> Sampler:
    """The sampler named by ``spec`` for ``task`` at condition ``y (k,)`` (see the module doc)."""
    name, arg, options = parse_spec(spec)
    constraint = task.constraint
    batch = options.get("batch")
    common = {"checker": checker, "seed": seed, **({"batch": batch} if batch else {})}
    if name in ("uniform", "project") and not arg:
        if "refine" in options:
            raise ManifoldgenError(f"the {name} sampler takes no refine option")
        return (UniformSampler if name == "uniform" else ProjectionSampler)(constraint, y, **common)
    if not arg:
        raise ManifoldgenError(f"unknown sampler '{spec}'; give one of: {SPEC_HELP}")
    if name == "pg":
        dataset = Dataset.load(arg)
        _check_robot(dataset.meta, task, f"dataset {arg}")
        return DatasetSampler(constraint, y, dataset.q, dataset.y, **common)
    return _model_sampler(name, arg, task, y, options.get("refine", MODEL_REFINE), common)


def _model_sampler(name: str, path: str, task: Task, y: np.ndarray, refine: int, common: dict) -> Sampler:
    from manifoldgen.models import get_model_class, load_model
    from manifoldgen.sampling import ModelSampler

    get_model_class(name)  # an unknown model name is reported with the known ones
    if not (Path(path) / "model.json").is_file():
        raise ManifoldgenError(f"no trained model at '{path}' (model.json missing); train one with "
                               f"`manifoldgen train {task.name} --model {name} ...` or fix the path")
    model = load_model(path)
    if model.name != name:
        raise ManifoldgenError(f"'{path}' holds a {model.name} model, not {name}; use '{model.name}:{path}'")
    _check_robot(model.meta, task, f"model {path}")
    return ModelSampler(task.constraint, y, model, refine=refine, **common)


def _check_robot(meta: dict, task: Task, what: str) -> None:
    robot = task.robot
    if meta.get("robot") != robot.name or list(meta.get("joints", [])) != list(robot.joints):
        raise ManifoldgenError(f"{what} is for robot '{meta.get('robot')}' with joints {meta.get('joints')}, "
                               f"not {robot.name} with {robot.joints}; use one made for this task")
