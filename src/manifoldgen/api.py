"""The Python API behind ``import manifoldgen as mg``: thin wrappers over the library, with argument checks.

Every function here checks its arguments' types at the boundary and raises one
:class:`~manifoldgen.errors.ManifoldgenError` naming the argument, what it takes and what it got; below
the boundary the library's own checks (ranges, files, robots, conditions) raise the same error type.
Heavy modules (torch, pinocchio, matplotlib) are imported inside the functions, when first needed.
Reference: ``docs/python-api.md``.
"""

from __future__ import annotations

import copy
import numbers
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from manifoldgen.errors import ManifoldgenError

if TYPE_CHECKING:
    import numpy as np

    from manifoldgen.dataset import Dataset
    from manifoldgen.models.base import ConditionalSampler
    from manifoldgen.planning.result import PlanResult
    from manifoldgen.sampling import Sampler
    from manifoldgen.scene import Scene
    from manifoldgen.space import ConstrainedSpace, PathReport
    from manifoldgen.tasks import Task

PathLike = str | os.PathLike


# ---------------------------------------------------------------------------------------------- checks
def _wrong(function: str, argument: str, expected: str, value: Any) -> ManifoldgenError:
    return ManifoldgenError(f"{function}: {argument} must be {expected}, got {type(value).__name__} {value!r:.80}")


def _pathlike(value: Any) -> bool:
    return isinstance(value, (str, os.PathLike))


def _integer(function: str, argument: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise _wrong(function, argument, "an integer", value)
    return int(value)


def _number(function: str, argument: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise _wrong(function, argument, "a number", value)
    return float(value)


def _flag(function: str, argument: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise _wrong(function, argument, "True or False", value)
    return value


def _seed(function: str, value: Any) -> int:
    from manifoldgen.runtime import check_seed

    return check_seed(_integer(function, "seed", value), f"{function}: seed")


def _optional_path(function: str, argument: str, value: Any) -> Path | None:
    if value is None:
        return None
    if not _pathlike(value):
        raise _wrong(function, argument, "None or a file path (str or os.PathLike)", value)
    return Path(value)


def _task(function: str, task: Any) -> Task:
    """A Task, or a task name / task file loaded with :func:`load_task`."""
    from manifoldgen.tasks import Task

    if isinstance(task, Task):
        return task
    if _pathlike(task):
        return load_task(task)
    raise _wrong(function, "task", "a Task (mg.load_task) or a task name or task .toml file", task)


def _scene(function: str, task: Task, scene: Any) -> Scene:
    """A Scene, or a scene name / scene file loaded with :func:`load_scene`."""
    from manifoldgen.scene import Scene

    if isinstance(scene, Scene):
        _check_scene(function, task, scene)
        return scene
    if _pathlike(scene):
        return load_scene(task, scene)
    raise _wrong(function, "scene", "a Scene (mg.load_scene) or a scene name or scene .json file", scene)


def _check_scene(function: str, task: Task, scene: Scene) -> None:
    """Refuse a Scene loaded for another robot, or for another task (its start, goal and condition sized for it)."""
    import numpy as np

    robot, fix = task.robot, "load the scene for this task: mg.load_scene(task, name)"
    if scene.robot and scene.robot != robot.name:
        raise ManifoldgenError(f"{function}: scene {scene.name!r} is for robot {scene.robot}, task {task.name} for "
                               f"{robot.name}; {fix}")
    sizes = {"start": robot.n, "goal": robot.n, "condition": task.condition.k}
    wrong = [f"{key} has {np.size(getattr(scene, key))}" for key, size in sizes.items()
             if np.shape(getattr(scene, key)) != (size,)]
    if wrong:
        raise ManifoldgenError(f"{function}: scene {scene.name!r} was loaded for another task ({', '.join(wrong)} "
                               f"values; task {task.name} on {robot.name} takes {robot.n} joint values and "
                               f"{task.condition.k} condition value(s)); {fix}")


def _scene_fingerprint(task: Task, scene: Scene) -> str:
    """SHA-256 of the scene's obstacles and held object as the task's robot meets them (not its start or goal)."""
    import hashlib
    import json

    return hashlib.sha256(json.dumps(scene.to_meta(task.robot), sort_keys=True).encode()).hexdigest()


# ---------------------------------------------------------------------------------------------- tasks, scenes
def builtin_tasks() -> dict[str, list[str]]:
    """The built-in task names, each with the robots it is defined for (its default robot first)."""
    from manifoldgen.tasks import builtin_tasks as files

    return {name: list(robots) for name, robots in files().items()}


def load_task(name_or_file: PathLike, robot: str | None = None) -> Task:
    """A built-in task by name (``"pose"``, ``"dualarm"``, ``"balance"``, ...; ``robot``: one of the robots it
    is defined for, default its default robot) or a task ``.toml`` file (docs/tasks.md)."""
    from manifoldgen.tasks import get_task

    if not _pathlike(name_or_file):
        raise _wrong("load_task", "name_or_file", "a task name or a task .toml file path", name_or_file)
    if robot is not None and not isinstance(robot, str):
        raise _wrong("load_task", "robot", "None or a robot name", robot)
    return get_task(os.fspath(name_or_file), robot)


def load_scene(task: Task | PathLike, name: PathLike) -> Scene:
    """A scene the task names (``"wall"``, ``"maze"``, ...) or a scene ``.json`` file for the task's robot;
    start and goal given as end-effector targets are solved onto the task's manifold."""
    from manifoldgen.scene import get_scene

    task = _task("load_scene", task)
    if not _pathlike(name):
        raise _wrong("load_scene", "name", "a scene name or a scene .json file path", name)
    return get_scene(task, os.fspath(name))


# ---------------------------------------------------------------------------------------------- data, models
def collect(task: Task | PathLike, per_condition: int = 1000, seed: int = 0, out: PathLike | None = None, *,
            conditions: Any = None, near_home: float = 0.0, anchors: bool = True, progress: bool = False) -> Dataset:
    """Collect ``per_condition`` constraint-satisfying configurations at each of the task's condition values
    (or ``conditions``, ``(V, k)``), as ``manifoldgen collect`` does: with ``anchors`` (and no ``near_home``) half
    the seeds lie around every scene's start and goal, and the dataset records the scenes; with ``out`` the
    dataset is also written there (``.npz``; an interrupted call resumes when repeated)."""
    from manifoldgen.data import collect as run_collect
    from manifoldgen.io import check_output_path
    from manifoldgen.scene import task_anchors

    task = _task("collect", task)
    per_condition = _integer("collect", "per_condition", per_condition)
    if per_condition <= 0:
        raise ManifoldgenError(f"collect: per_condition must be a positive number of rows, got {per_condition}")
    seed = _seed("collect", seed)
    near_home = _number("collect", "near_home", near_home)
    anchors, progress = _flag("collect", "anchors", anchors), _flag("collect", "progress", progress)
    out = _optional_path("collect", "out", out)
    if out is not None:
        check_output_path(out, [task.file], what="collect: out", suffixes=(".npz",), kind="dataset")
    found = task_anchors(task) if anchors and not near_home else None
    return run_collect(task, per_condition, seed, out, conditions=conditions, near_home=near_home, anchors=found,
                       progress=progress)


def train(dataset: Dataset | PathLike, model: str = "auto", seed: int = 0, out: PathLike | None = None, *,
          epochs: int | None = None, progress: bool = False, **hyper) -> ConditionalSampler:
    """Train a conditional model ``p(q | y)`` on ``dataset`` (a :class:`Dataset` or a dataset file) and return it.

    ``model``: ``auto`` (as ``manifoldgen train``: the candidates trained, scored on held-out rows and raced on the
    task's scenes, the fastest kept; :mod:`manifoldgen.selection`), ``cvae``, ``cfm``, ``cgan``, ``wgan``,
    ``flow`` or a registered / ``module:Class`` name; ``hyper``: its hyper-parameters (``latent=6``,
    ``hidden=[256, 256]``, ...; an unknown one lists the known ones; not with ``auto``). With ``out`` the model
    directory (``model.json`` + ``model.safetensors``; with ``auto`` also ``selection.json`` and ``candidates/``)
    is written there. Results are reproducible for a seed and a torch thread count
    (``manifoldgen.runtime.set_threads``)."""
    import tempfile

    from manifoldgen.dataset import Dataset
    from manifoldgen.io import check_output_path
    from manifoldgen.models import get_model_class
    from manifoldgen.selection import SELECTION_FILE, check_recorded_scenes, select_model
    from manifoldgen.training import OUTPUT_FILES

    source = None
    if _pathlike(dataset):
        source = Path(dataset)
        dataset = Dataset.load(source)
    elif not isinstance(dataset, Dataset):
        raise _wrong("train", "dataset", "a Dataset (mg.collect) or a dataset .npz file path", dataset)
    if not isinstance(model, str):
        raise _wrong("train", "model", "a model name such as 'cvae'", model)
    seed = _seed("train", seed)
    progress = _flag("train", "progress", progress)
    epochs = None if epochs is None else _integer("train", "epochs", epochs)
    if epochs is not None and epochs <= 0:
        raise ManifoldgenError(f"train: epochs must be a positive number (None: the model's own), got {epochs}")
    out = _optional_path("train", "out", out)
    if out is not None:
        check_output_path(out, [source], directory=True, writes=OUTPUT_FILES + (SELECTION_FILE, "candidates"),
                          what="train: out")
    if model == "auto":
        if hyper:
            raise ManifoldgenError(f"train: hyper-parameters ({', '.join(hyper)}) set one model's; name it, e.g. "
                                   "model='cvae'")
        with tempfile.TemporaryDirectory(prefix="manifoldgen-train-") as scratch:
            return select_model(dataset, out if out is not None else scratch, seed=seed, epochs=epochs,
                                progress=progress)[0]
    check_recorded_scenes(dataset)  # a model keeps them in its meta: read whole before training
    net = get_model_class(model)(**hyper)
    net.fit(dataset, epochs=epochs, seed=seed, progress=progress, out=out)
    return net


def load_model(directory: PathLike) -> ConditionalSampler:
    """A trained model from its directory (``model.json`` + ``model.safetensors``; validated, never unpickled)."""
    from manifoldgen.models import load_model as read

    if not _pathlike(directory):
        raise _wrong("load_model", "directory", "a model directory path", directory)
    return read(directory)


def pretrained_model_dir(name: str = "panda-pose-cvae") -> Path:
    """The directory of a model shipped with the package (the panda ``pose`` CVAE)."""
    from manifoldgen.models import pretrained_model_dir as shipped

    if not isinstance(name, str):
        raise _wrong("pretrained_model_dir", "name", "the name of a shipped model", name)
    return shipped(name)


# ---------------------------------------------------------------------------------------------- sampling
def _space(function: str, task: Any, scene: Any) -> tuple[Task, Scene, ConstrainedSpace]:
    """The task, the scene and the space of the scene's query (the task's constraint at the scene's condition,
    the scene's obstacles and held object)."""
    from manifoldgen.space import ConstrainedSpace

    task = _task(function, task)
    scene = _scene(function, task, scene)
    y = task.condition.check(scene.condition)[0]
    return task, scene, ConstrainedSpace(task.constraint, y, scene.checker(task.robot))


def _sampler_for(function: str, argument: str, space: ConstrainedSpace, model: Any, seed: int, refine: int | None,
                 batch: int | None) -> tuple[Sampler, str]:
    """The sampler ``model`` names or is, for ``space``, and its description for a path file's meta."""
    from manifoldgen.dataset import Dataset
    from manifoldgen.models.base import ConditionalSampler
    from manifoldgen.provenance import check_made_for
    from manifoldgen.runtime import REFINE
    from manifoldgen.sampling import DatasetSampler, model_sampler
    from manifoldgen.specs import LIMITS, make_sampler

    refine = None if refine is None else _integer(function, "refine", refine)
    batch = None if batch is None else _integer(function, "batch", batch)
    for name, value in (("refine", refine), ("batch", batch)):  # the ranges of the spec string's options
        low, high = LIMITS[name]
        if value is not None and not low <= value <= high:
            raise ManifoldgenError(f"{function}: {name} must be from {low} to {high:,}, got {value}")
    common = {"seed": seed, **({"batch": batch} if batch is not None else {})}
    if isinstance(model, str):
        options = [f"{key}={value}" for key, value in (("refine", refine), ("batch", batch)) if value is not None]
        spec = ",".join([model, *options])
        return make_sampler(spec, space, seed), spec
    if isinstance(model, ConditionalSampler):
        refine = REFINE if refine is None else refine
        return model_sampler(space, model, refine=refine, **common), f"{model.label}:(in memory),refine={refine}"
    if isinstance(model, Dataset):
        if refine is not None:
            raise ManifoldgenError(f"{function}: refine applies to a model's samples; a Dataset's rows are drawn as "
                                   "they are: leave refine out")
        check_made_for(model.meta, space.constraint, "the dataset")
        return DatasetSampler(space, model.q, model.y, **common), "pg:(in memory)"
    raise _wrong(function, argument, "a sampler spec (uniform, project, pg:DATASET.npz, MODEL:DIR), a trained model "
                 "(mg.load_model, mg.train) or a Dataset", model)


def sampler(task: Task | ConstrainedSpace | PathLike, scene: Scene | PathLike | None = None,
            model: Any = "project", *, seed: int = 0, refine: int | None = None, batch: int | None = None) -> Sampler:
    """A sampler (paper Algorithm 1) of valid configurations for the scene's query: ``model`` is a spec string
    (``"uniform"``, ``"project"``, ``"pg:DATASET.npz"``, ``"cvae:DIR"``, options ``,refine=N,batch=B``), a
    trained model object or a :class:`Dataset` (the paper's PG baseline). ``refine``: projection iterations per
    model sample (default 2). ``task`` may instead be a ``ConstrainedSpace`` (``scene`` left out).
    ``s.sample()`` gives one configuration ``(n,)``, ``s.sample_many(m)`` ``(m, n)``; ``s.stats`` counts."""
    from manifoldgen.space import ConstrainedSpace

    seed = _seed("sampler", seed)
    if isinstance(task, ConstrainedSpace):
        if scene is not None:
            raise ManifoldgenError("sampler: give a ConstrainedSpace without a scene (it has its obstacles), "
                                   "or a task and a scene")
        space = task
    elif scene is None:
        raise ManifoldgenError("sampler: give the scene (mg.load_scene or a scene name) after the task: the "
                               "sampler serves the scene's query (its condition, obstacles and held object)")
    else:
        task, scene, space = _space("sampler", task, scene)
    made = _sampler_for("sampler", "model", space, model, seed, refine, batch)[0]
    if scene is not None:
        made.scene = (scene.name, _scene_fingerprint(task, scene))
    return made


# ---------------------------------------------------------------------------------------------- planning
@dataclass
class QueryResult:
    """One planning query's outcome: ``result`` (the planner's :class:`PlanResult`: ``path (K, n)``, times,
    counts) and ``meta`` (what a path file records: task, scene, query, planner, sampler, ``result`` and
    ``validation``). :meth:`to_dict` has the same keys whether the query was solved or not."""

    result: PlanResult
    meta: dict

    @property
    def solved(self) -> bool:
        return bool(self.result.solved)

    @property
    def path(self) -> np.ndarray:
        """Waypoints ``(K, n)``; ``(0, n)`` when unsolved."""
        return self.result.path

    @property
    def valid(self) -> bool:
        """The package's dense check of the returned path (False when unsolved)."""
        return bool(self.meta["validation"]["valid"])

    def why(self) -> str:
        """One line: the outcome, and when unsolved what held the search back."""
        return self.result.why()

    def to_dict(self) -> dict:
        """JSON-ready: the path file's meta (``result``, ``validation``, the query, the task), without the path."""
        return copy.deepcopy(self.meta)

    @classmethod
    def load(cls, file: PathLike, task: Task | PathLike | None = None, *, trust_code: bool = False) -> QueryResult:
        """A path file (``manifoldgen plan -o`` or :meth:`save`), checked whole
        (:func:`manifoldgen.query.read_path_file`; ``task`` (a Task, a task name or task file; refused unless the
        file was made for it), ``trust_code``: for a file whose task names a user's constraint type)."""
        from manifoldgen.planning.result import PlanResult, path_length
        from manifoldgen.query import read_path_file

        if not _pathlike(file):
            raise _wrong("QueryResult.load", "file", "a file path (str or os.PathLike)", file)
        trust_code = _flag("QueryResult.load", "trust_code", trust_code)
        task = None if task is None else _task("QueryResult.load", task)
        meta, path, _ = read_path_file(file, task, trust_code=trust_code)
        done = meta.get("result", {})
        result = PlanResult(True, path, float(done.get("time_s", 0.0)), int(done.get("iterations", 0)),
                            int(done.get("samples_drawn", 0)), int(done.get("projections", 0)),
                            str(done.get("planner", meta.get("planner", ""))), path_length(path),
                            dict(done.get("extras", {})))
        return cls(result, meta)

    def save(self, file: PathLike) -> Path:
        """Write the path file (``path (K, n)`` + ``meta``; atomic), as ``manifoldgen plan -o`` does."""
        from manifoldgen.io import check_output_path
        from manifoldgen.query import save_path

        if not _pathlike(file):
            raise _wrong("QueryResult.save", "file", "a file path (str or os.PathLike)", file)
        file = check_output_path(file, what="QueryResult.save: file", suffixes=(".npz",), kind="path")
        if not self.result.solved:
            raise ManifoldgenError(f"QueryResult.save: the query was not solved, so there is no path to write "
                                   f"({self.result.why()})")
        save_path(file, self.result, self.meta, what="QueryResult.save: file")
        return file


def _settings(planner: str, settings: Any) -> dict:
    from manifoldgen.planning import planner_settings

    if settings is None:
        return {}
    if not isinstance(settings, dict) or not all(isinstance(k, str) for k in settings):
        raise _wrong("plan", "settings", "None or a dict of planner setting name -> value", settings)
    known = planner_settings(planner)
    unknown = sorted(set(settings) - set(known))
    if unknown:
        raise ManifoldgenError(f"plan: unknown {planner} setting(s) {', '.join(unknown)}; known: {', '.join(known)}")
    return dict(settings)


def plan(task: Task | PathLike, scene: Scene | PathLike, sampler: Any = "project", planner: str = "rrtconnect", *,
         seed: int = 0, time_limit: float = 30.0, local: str = "auto", smooth: bool = False,
         settings: dict | None = None) -> QueryResult:
    """Plan the scene's query, as ``manifoldgen plan`` does: the path comes back re-checked densely.

    ``sampler``: a spec string (see :func:`sampler`), a trained model object, a :class:`Dataset`, or a
    ``Sampler`` made by :func:`sampler` for this task and scene (the query is then planned in its space).
    ``planner``: ``rrtconnect``, ``rrt``, ``prm``, ``kpiece``, ``sbl``, ``cbirrt``; ``settings``: its settings
    (``{"range": 0.8}``; the task file's ``[planner]`` defaults apply first). ``time_limit`` in seconds."""
    import numpy as np

    from manifoldgen.query import run_query
    from manifoldgen.sampling import Sampler

    task = _task("plan", task)
    scene = _scene("plan", task, scene)
    if not isinstance(planner, str):
        raise _wrong("plan", "planner", "a planner name such as 'rrtconnect'", planner)
    if not isinstance(local, str):
        raise _wrong("plan", "local", "'auto', 'interpolate' or 'project'", local)
    smooth = _flag("plan", "smooth", smooth)
    seed = _seed("plan", seed)
    time_limit = _number("plan", "time_limit", time_limit)
    from manifoldgen.planning.base import check_time_limit
    check_time_limit(time_limit, "plan: time_limit")
    values = _settings(planner, settings)
    if isinstance(sampler, str):  # exactly the command line's query
        result, meta = run_query(task, scene, sampler, planner, seed=seed, time_limit=time_limit, local=local,
                                 smooth=smooth, settings=values)
        return QueryResult(result, meta)
    if isinstance(sampler, Sampler):
        space, made = sampler.space, sampler
        y = task.condition.check(scene.condition)[0]
        if space.constraint.spec() != task.constraint.spec() or not np.allclose(space.y, y):
            raise ManifoldgenError("plan: the sampler was made for another task or condition; make it with "
                                   "mg.sampler(task, scene, ...) for this task and scene")
        if sampler.scene is not None and sampler.scene[1] != _scene_fingerprint(task, scene):
            raise ManifoldgenError(f"plan: the sampler was made for scene {sampler.scene[0]!r}, whose obstacles or "
                                   f"held object are not those of scene {scene.name!r}; make it with "
                                   "mg.sampler(task, scene, ...) for this scene")
        label = type(sampler).__name__
    else:
        space = _space("plan", task, scene)[2]
        made, label = _sampler_for("plan", "sampler", space, sampler, seed, None, None)
    from manifoldgen.query import plan_query

    return QueryResult(*plan_query(task, scene, space, made, label, planner, seed=seed, time_limit=time_limit,
                                   local=local, smooth=smooth, settings=values))


def check_path(task: Task | PathLike, scene: Scene | PathLike, path: Any, *,
               resolution: float | None = None) -> PathReport:
    """Check ``path`` (waypoints ``(K, n)``, or a :class:`QueryResult`) state by state every ``resolution``
    (default 0.005) along its straight segments: joint limits, the constraint within tolerance, inequalities,
    collisions with the scene and the held object. Returns a ``PathReport`` (``valid``, ``worst_violation``,
    ``reason``, ``segment``, ``states_checked``, ``resolution``); independent of how the path was made."""
    import numpy as np

    from manifoldgen.space import ConstrainedSpace, ValidationSettings

    task = _task("check_path", task)
    scene = _scene("check_path", task, scene)
    if isinstance(path, QueryResult):
        path = path.path
    try:
        waypoints = np.asarray(path, dtype=float)
    except (TypeError, ValueError):
        raise _wrong("check_path", "path", "waypoints (K, n) as an array of numbers, or a QueryResult", path) from None
    settings = ValidationSettings() if resolution is None else \
        ValidationSettings(resolution=_number("check_path", "resolution", resolution))
    y = task.condition.check(scene.condition)[0]
    return ConstrainedSpace(task.constraint, y, scene.checker(task.robot), settings).validate_path(waypoints)
