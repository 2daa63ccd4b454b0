"""What a file shows: its kind, task (robot + constraint), configurations and scene.

Kinds: ``path`` (an .npz with ``path (K, n)``), ``dataset`` (an .npz with ``q (N, n)`` and
``y (N, k)``: datasets and sample files), ``scene`` (a scene .json: start and goal) and
``task`` (a task .toml: its first scene's start and goal, else its home configuration).
The task is rebuilt from the file's meta alone (:func:`~manifoldgen.tasks.task_from_meta`), or is the task given
for it (needed for a user's ``module:Class`` constraint: reading a file imports no code).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from manifoldgen.dataset import Dataset
from manifoldgen.errors import ManifoldgenError, file_reader, not_a_file
from manifoldgen.io import load_npz, npz_kind
from manifoldgen.provenance import check_task_copies
from manifoldgen.query import read_path_file
from manifoldgen.scene import Scene, get_scene
from manifoldgen.tasks import Task, builtin_tasks, get_task, task_from_meta

KINDS = "a path or dataset/sample .npz, a scene .json, a task .toml or a built-in task name"


@dataclass
class ViewSource:
    """A file to show. ``q (N, n)``: path waypoints, dataset rows, or start and goal (or home);
    ``y (N, k)``: the condition of each row; ``scene``: obstacles and held tool (may be empty)."""

    kind: str
    file: Path
    meta: dict
    task: Task
    q: np.ndarray
    y: np.ndarray
    scene: Scene
    title: str


@file_reader
def read_source(file: str | Path, task: str | None = None, *, trust_code: bool = False) -> ViewSource:
    """Read ``file``; ``task`` names the task of a scene .json (default: the built-in task that lists
    the scene, else ``pose`` for the scene's robot), or of an .npz (checked against its meta; default: the
    task in its meta; ``trust_code``: see :func:`~manifoldgen.tasks.task_from_spec`)."""
    file = Path(file)
    if not file.exists() and str(file) in builtin_tasks():  # a built-in task's name: its default robot's file
        return _read_task(next(iter(builtin_tasks()[str(file)].values())))
    if not file.is_file():
        raise ManifoldgenError(f"{not_a_file(file)}; give {KINDS}")
    suffix = file.suffix.lower()
    if suffix == ".npz":
        return _read_npz(file, None if task is None else get_task(task), trust_code)
    if suffix == ".json":
        return _read_scene(file, task)
    if suffix == ".toml":
        return _read_task(file)
    raise ManifoldgenError(f"cannot show {file}: unknown file kind '{suffix or file.name}'; give {KINDS}")


def _read_npz(file: Path, task: Task | None, trust_code: bool) -> ViewSource:
    kind = npz_kind(file)  # its meta alone: the reader below loads the arrays once, with its own checks
    if kind is None:
        load_npz(file, ())  # refuses a damaged or foreign .npz, naming why
    if kind == "path":
        meta, path, t = read_path_file(file, task, trust_code=trust_code)
        y = np.broadcast_to(np.asarray(meta["condition"], float), (len(path), t.condition.k))
        scene = Scene.from_meta(meta)
        return ViewSource("path", file, meta, t, path, y, scene,
                          f"{t.robot.name} {t.name}, scene {scene.name or '?'}: {len(path)} waypoints")
    if kind in ("dataset", "samples"):
        data = Dataset.load(file)  # the dataset checks: arrays, meta kinds, its task's copies below
        t = task_from_meta(data.meta, task=task, trust_code=trust_code, what=str(file))
        check_task_copies(data.meta, t.constraint, str(file))
        q, y = data.q, data.y
        _check_width(q, t, file)
        if not len(q):
            raise ManifoldgenError(f"{file} holds no rows: nothing to show; give a dataset or samples file with rows")
        return ViewSource("dataset", file, data.meta, t, q, y, Scene("", [], None, q[:0], q[:0], y[:0]),
                          f"{t.robot.name} {t.name} {kind}: {len(q)} rows")
    raise ManifoldgenError(f"cannot show {file}: an .npz without 'path' or 'q' and 'y'; give {KINDS}")


def _read_scene(file: Path, task: str | None) -> ViewSource:
    try:
        data = json.loads(file.read_text())
    except ValueError as exc:
        raise ManifoldgenError(f"{file} is not valid JSON ({exc}); fix the file") from exc
    if not isinstance(data, dict) or "obstacles" not in data:
        raise ManifoldgenError(f"cannot show {file}: a .json without 'obstacles' is not a scene; give {KINDS}")
    scene = Scene.from_json(file.read_text(), str(file))
    if not scene.robot and task is None:
        raise ManifoldgenError(f"scene {file} names no robot; add \"robot\": \"<name>\" or pass --task")
    try:  # a task given is taken as plan takes it (its default robot): get_scene refuses a scene for another robot
        t = get_task(task, None) if task else get_task(_task_listing(file) or "pose", scene.robot or None)
    except ManifoldgenError as exc:
        raise ManifoldgenError(f"{exc}; for a scene of another task pass --task TASK.toml" if task is None
                               else str(exc)) from exc
    scene = get_scene(t, str(file))  # checked against the task; end-effector targets solved
    q = np.stack([scene.start, scene.goal])
    return ViewSource("scene", file, {"robot": t.robot.name}, t, q, np.stack([scene.condition] * 2), scene,
                      f"{t.robot.name} {t.name}, scene {scene.name}: start and goal")


def _read_task(file: Path) -> ViewSource:
    t = get_task(str(file))
    if t.scenes:
        name = next(iter(t.scenes))
        scene = get_scene(t, name)
        q, y = np.stack([scene.start, scene.goal]), np.stack([scene.condition] * 2)
        what = f"scene {name}: start and goal"
    else:
        scene = Scene("", [], None, t.home[:0], t.home[:0], t.home_condition)
        q, y, what = t.home[None], t.home_condition[None], "home configuration"
    _check_width(q, t, file)
    return ViewSource("task", file, {"robot": t.robot.name}, t, q, y, scene, f"{t.robot.name} {t.name}, {what}")


def _task_listing(scene_file: Path) -> str | None:
    """The built-in task file that names ``scene_file`` among its scenes, if any."""
    for robots in builtin_tasks().values():
        for task_file in robots.values():
            if any(Path(s).resolve() == scene_file.resolve() for s in get_task(str(task_file)).scenes.values()):
                return str(task_file)
    return None


def _check_width(q: np.ndarray, task: Task, file: Path) -> None:
    if q.ndim != 2 or q.shape[1] != task.robot.n:
        raise ManifoldgenError(f"{file}: configurations of shape {q.shape} do not fit the {task.robot.n} joints of "
                               f"task {task.name} on {task.robot.name}")


def traced_frames(task: Task, limit: int = 2) -> list[str]:
    """The robot frames the task's constraint names (its end effectors), at most ``limit``."""
    found: list[str] = []

    def walk(value) -> None:
        if isinstance(value, dict):
            for v in value.values():
                walk(v)
        elif isinstance(value, list):
            for v in value:
                walk(v)
        elif isinstance(value, str) and task.robot.model.existFrame(value) and value not in found:
            found.append(value)

    walk(task.constraint.spec())
    return found[:limit]
