"""Sampler specifications, as the CLI and the benchmarks name them.

``uniform`` (rejection in the joint limits), ``project`` (uniform seeds projected),
``pg:DATASET.npz`` (the paper's precomputed-graph baseline: rows of a dataset) or
``MODEL:DIR`` (a trained model directory, e.g. ``cvae:runs/cvae``; any registered model
name, or ``model`` for whichever model the directory holds). Options follow after commas:
``cvae:runs/cvae,refine=0,batch=2048``; model samples get the projection iterations the model's training measured
they need (``runtime.REFINE`` for a model that records none) unless ``refine`` says otherwise (``refine=0``: raw
model samples, the paper's setting).
"""

from __future__ import annotations

from pathlib import Path

from manifoldgen.dataset import Dataset
from manifoldgen.errors import ManifoldgenError
from manifoldgen.provenance import check_made_for, check_model_for
from manifoldgen.sampling import DatasetSampler, ProjectionSampler, Sampler, UniformSampler
from manifoldgen.space import ConstrainedSpace

SPEC_HELP = ("uniform, project, pg:DATASET.npz, or MODEL:DIR (e.g. cvae:runs/cvae, or model:DIR for whichever model "
             "DIR holds; options: ,refine=N,batch=B)")
OPTIONS = {"refine": int, "batch": int}
# inclusive ranges of the options; a sampler projects its whole batch before the first row (about 10 s at the top)
LIMITS = {"refine": (0, 1000), "batch": (1, 100_000)}


def parse_spec(spec: str) -> tuple[str, str, dict[str, int]]:
    """``'cvae:dir,refine=2'`` -> ``('cvae', 'dir', {'refine': 2})``. Commas separate the options, except in the
    longest start of the spec that names an existing path (``cvae:runs/a,b,refine=2``: the folder ``runs/a,b``)."""
    parts = spec.strip().split(",")
    cut = 1  # parts[:cut] are the head NAME[:PATH], the others options
    for k in range(len(parts), 1, -1):
        path = ",".join(parts[:k]).partition(":")[2]
        if path and Path(path).exists():
            cut = k
            break
    name, _, arg = ",".join(parts[:cut]).partition(":")
    parsed = {}
    for option in parts[cut:]:
        key, eq, value = option.partition("=")
        if key not in OPTIONS or not eq:
            raise ManifoldgenError(f"bad sampler option '{option}' in '{spec}'; options: "
                                   f"{', '.join(f'{k}=N' for k in OPTIONS)} (commas separate them; a path with a "
                                   "comma is read whole when it exists)")
        if key in parsed:
            raise ManifoldgenError(f"sampler option {key} is given twice in '{spec}'; give each option once")
        try:
            parsed[key] = OPTIONS[key](value)
        except ValueError as exc:
            raise ManifoldgenError(f"sampler option {key} must be an integer, got '{value}'") from exc
        low, high = LIMITS[key]
        if not low <= parsed[key] <= high:
            raise ManifoldgenError(f"sampler option {key}={parsed[key]} in '{spec}' must be from {low} to {high:,}")
    return name, arg, parsed


def make_sampler(spec: str, space: ConstrainedSpace, seed: int) -> Sampler:
    """The sampler named by ``spec`` (see the module doc) for ``space`` (constraint, condition,
    collision checker)."""
    name, arg, options = parse_spec(spec)
    batch = options.get("batch")
    common = {"seed": seed, **({"batch": batch} if batch else {})}
    if name in ("uniform", "project") and arg:
        raise ManifoldgenError(f"the {name} sampler takes no path (got '{name}:{arg}'); give {name} alone, or "
                               "MODEL:DIR for a trained model")
    if name in ("uniform", "project", "pg") and "refine" in options:  # their samples are on the manifold or raw
        raise ManifoldgenError(f"the {name} sampler takes no refine option (only a trained model's samples are "
                               "refined); leave refine out")
    if name in ("uniform", "project"):
        return (UniformSampler if name == "uniform" else ProjectionSampler)(space, **common)
    if not arg:
        raise ManifoldgenError(f"unknown sampler '{spec}'; give one of: {SPEC_HELP}")
    if name == "pg":
        dataset = Dataset.load(arg)
        check_made_for(dataset.meta, space.constraint, f"dataset {arg}")
        return DatasetSampler(space, dataset.q, dataset.y, **common)
    return _model_sampler(name, arg, space, options.get("refine"), common)


def _model_sampler(name: str, path: str, space: ConstrainedSpace, refine: int | None, common: dict) -> Sampler:
    from manifoldgen.models import MODELS, open_model
    from manifoldgen.sampling import model_sampler

    if name != "model" and name not in MODELS.names():
        MODELS.get(name)  # an unknown model name is reported with the known ones
    if not (Path(path) / "model.json").is_file():
        raise ManifoldgenError(f"no trained model at '{path}' (model.json missing); train one with "
                               f"`manifoldgen train DATASET --model {name} ...` or fix the path")
    model = open_model(path)
    if name not in ("model", model.name):
        raise ManifoldgenError(f"'{path}' holds a {model.name} model, not {name}; use '{model.name}:{path}'")
    check_model_for(model, space.constraint, f"model {path}")
    return model_sampler(space, model, refine=refine, **common)
