"""Tasks are data: a TOML task file names the robot, its planning group, locked joints, the
constraint(s) with their parameters and training condition values, and the scenes.

The built-in tasks are such files, beside this module (``pose-panda.toml``, ...). Wherever a
command takes a task name it takes a task file path too. A :class:`Task` describes itself
fully in :meth:`Task.spec` (robot by name and URDF hash, every locked joint, the constraint's
full spec), which every dataset, model and path file stores, and :func:`task_from_spec`
rebuilds it from that alone. The task file format is documented in ``docs/tasks.md``.

Reading a file never imports code: a file whose constraint is a user's ``module:Class`` is refused unless
the caller gives the task file it was made from (``task=``, checked against the file) or trusts the code
(``trust_code=True``: the module is imported from ``sys.path``). The ``task_file`` a spec records is
information only. A task file's own ``module:Class`` is imported from its folder (the user named the file).
"""

from __future__ import annotations

import contextlib
import re
import sys
import tomllib
from dataclasses import dataclass, field
from functools import lru_cache, partial
from pathlib import Path

import numpy as np

from manifoldgen.constraint_callbacks import central_difference
from manifoldgen.constraints import Condition, Constraint, ConstraintSet, build_constraint, own_jacobian, project
from manifoldgen.errors import ManifoldgenError, file_reader, not_a_file, short, unknown_name
from manifoldgen.io import read_toml_file
from manifoldgen.planning import PLANNERS, planner_settings
from manifoldgen.provenance import check_made_for
from manifoldgen.robot import Robot, find_robot, resolve_robot
from manifoldgen.settings import check_settings

BUILTIN_DIR = Path(__file__).resolve().parent
TASK_KEYS = {"name": "task name", "description": "one line for `manifoldgen tasks`",
             "default": "this robot is the default for the task name", "robot": "example-robot-data name or URDF path",
             "srdf": "SRDF path", "group": "planning group joints", "floating_base": "true for a free-flying base",
             "base_bounds": "[[x, y, z low], [x, y, z high]] of a floating base", "locked": "joint = value table",
             "home": "a configuration near the manifold (projected)", "home_condition": "the condition of home",
             "constraints": "[[constraints]] tables", "scenes": "name = scene file table",
             "attached": "[attached] table: an object the robot holds (a tray), as a scene's held object",
             "planner": "[planner] table: our planners' default settings for this task (--set wins)"}
TASK_TYPES = {"name": str, "description": str, "default": bool, "robot": str, "srdf": str, "group": list,
              "floating_base": bool, "base_bounds": list, "locked": dict, "home": list, "home_condition": list,
              "constraints": list, "scenes": dict, "attached": dict, "planner": dict}  # what each key's value is
TYPE_WORDS = {str: "a string", bool: "true or false", list: "a list [...]", dict: "a table"}
HOME_SEEDS = 256  # uniform seeds projected when a task gives no home
HOME_MOVED = 1e-6  # the most a stored (projected) home may move when projected again


@dataclass
class Task:
    """A robot with a constraint; ``home (n,)`` satisfies it at ``home_condition (k,)``; ``scenes``
    maps scene names to scene files."""

    name: str
    robot: Robot
    constraint: Constraint
    home: np.ndarray
    home_condition: np.ndarray
    notes: str = ""
    scenes: dict[str, Path] = field(default_factory=dict)
    file: Path | None = None  # the task file it was read from
    attached: dict | None = None  # an object the robot holds in every scene (JSON-ready, see shapes.Attached)
    planner: dict = field(default_factory=dict)  # our planners' default settings for this task (key -> value)

    @property
    def condition(self) -> Condition:
        return self.constraint.condition

    def spec(self) -> dict:
        """Everything that defines the task, JSON-ready: :func:`task_from_spec` rebuilds it."""
        r = self.robot
        return {"name": self.name, "description": self.notes, "robot": r.identity, "robot_source": r.source,
                "srdf_source": None if r.srdf is None else str(r.srdf),
                "group": [j for j in r.joints if j not in _base_joints(r)], "floating_base": r.floating_base,
                "base_bounds": r.base_bounds.tolist(), "locked": r.locked, "constraint": self.constraint.spec(),
                "home": self.home.tolist(), "home_condition": self.home_condition.tolist(),
                "task_file": None if self.file is None else str(self.file),
                **({"attached": self.attached} if self.attached is not None else {}),
                **({"planner": self.planner} if self.planner else {})}

    def meta(self) -> dict:
        """The ``meta`` fields every file made for this task carries (an outside checker needs only these)."""
        return {"task": self.spec(), "robot": self.robot.name, "joints": self.robot.joints,
                "locked": self.robot.locked, "floating_base": self.robot.floating_base,
                "constraint": self.constraint.spec(), "tolerance": self.constraint.tolerance.tolist(),
                "condition": {"names": list(self.condition.names), "units": list(self.condition.units),
                              "values": self.condition.grid.tolist()}}


def _base_joints(robot: Robot) -> list[str]:
    return robot.joints[:6] if robot.floating_base else []


def code_types(spec) -> list[str]:
    """The ``module:Class`` types anywhere in ``spec`` (a task or constraint spec): code that building it imports."""
    if isinstance(spec, dict):
        own = [spec["type"]] if isinstance(spec.get("type"), str) and ":" in spec["type"] else []
        return own + [t for value in spec.values() for t in code_types(value)]
    if isinstance(spec, list):
        return [t for value in spec for t in code_types(value)]
    return []


def task_from_spec(spec: dict, robot_hint: str | None = None, *, trust_code: bool = False,
                   what: str = "the file") -> Task:
    """Rebuild the task :meth:`Task.spec` described (no registry lookup, no task file). A spec naming a
    ``module:Class`` type is refused unless ``trust_code``: then the module is imported from ``sys.path``
    as it stands (``task_file`` is never added to it)."""
    code = code_types(spec)
    if code and not trust_code:
        modules = ", ".join(sorted({t.partition(":")[0] for t in code}))
        raise ManifoldgenError(f"{what} names the user constraint type {', '.join(code)}, and reading a file never "
                               "imports code: pass the task file it was made from with --task FILE (checked against "
                               f"the file), or --trust-code to import {modules} from PYTHONPATH (runs that code)")
    robot_field = spec["robot"]
    source = find_robot(robot_field, robot_hint or spec.get("robot_source")) if isinstance(robot_field, dict) \
        else robot_field
    srdf = spec.get("srdf_source")
    robot = Robot.load(source, list(spec["group"]), reference=spec.get("locked") or {},
                       floating_base=bool(spec.get("floating_base", False)),
                       srdf=srdf if srdf and Path(srdf).is_file() else None,
                       **({"base_bounds": spec["base_bounds"]} if spec.get("base_bounds") else {}))
    constraint = build_constraint(robot, spec["constraint"])
    task = _finish(spec["name"], robot, constraint, spec.get("home"), spec.get("home_condition"),
                   spec.get("description", ""), {})
    if spec.get("home") is not None:  # written projected: a home the projection moves was edited
        moved = float(np.abs(task.home - _numbers(spec["home"], "home")).max())
        if moved > HOME_MOVED:
            raise ManifoldgenError(f"{what}: its task's home is off its constraint (projecting it moves a joint "
                                   f"{moved:.3g}); the file was edited: make it again")
    task.file = Path(spec["task_file"]) if spec.get("task_file") else None
    task.attached = spec.get("attached")
    task.planner = dict(spec.get("planner") or {})
    return task


def code_files(spec: dict) -> dict[str, str]:
    """Module -> the file this process imported it from, for each ``module:Class`` type in ``spec`` (a task
    built from ``spec`` here imported them all)."""
    modules = sorted({t.partition(":")[0] for t in code_types(spec)})
    return {module: getattr(sys.modules.get(module), "__file__", None) for module in modules}


def task_in_child(spec: dict, files: dict[str, str]) -> Task:
    """In another process, the task that ``spec`` built here: its user modules imported from the same ``files``
    (:func:`code_files`, each a file), which the user already let this process run; a module found elsewhere is
    refused."""
    import importlib

    for module, file in files.items():
        path = Path(file)
        with _importable_from(path.parents[module.count(".") + (path.stem == "__init__")]):
            found = getattr(importlib.import_module(module), "__file__", None)
        if found != file:
            raise ManifoldgenError(f"module {module} imports {found} in a child process, not {file}: an installed "
                                   "module of that name comes first; rename your module")
    return task_from_spec(spec, trust_code=True)


def task_from_meta(meta: dict, robot_hint: str | None = None, *, task: Task | None = None,
                   trust_code: bool = False, what: str = "the file") -> Task:
    """The task a dataset, model or path file (``what``, for messages) was made for: ``task`` (a task the
    user gave, refused unless the file was made for it), else rebuilt from the file's ``meta`` alone
    (see :func:`task_from_spec` for ``trust_code``)."""
    if task is not None:
        check_made_for(meta if isinstance(meta, dict) else {}, task.constraint, what)
        return task
    spec = meta.get("task") if isinstance(meta, dict) else None
    if not isinstance(spec, dict):
        raise ManifoldgenError("the file's meta has no task specification (made by manifoldgen before 0.2); "
                               "recollect the dataset or retrain the model with this version")
    try:
        return task_from_spec(spec, robot_hint, trust_code=trust_code, what=what)
    except ManifoldgenError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, RuntimeError) as exc:  # a damaged file
        why = (str(exc).strip().splitlines() or [""])[0][:120]
        raise ManifoldgenError(f"the file's task specification is damaged ({type(exc).__name__}: {why}); "
                               "regenerate the file") from None


HOME_SLACK = 1e-3  # rad or m: how far past a joint limit a task file's home may lie (rounding)


def _finish(name: str, robot: Robot, constraint: Constraint, home, home_condition, notes: str,
            scenes: dict[str, Path]) -> Task:
    """A task with a home on the manifold: ``home`` projected, else the first of HOME_SEEDS uniform seeds that converges."""
    condition = constraint.condition
    y = condition.grid[0] if home_condition is None else _home_condition(condition, home_condition)
    seeds = (_numbers(home, "home")[None] if home is not None
             else robot.sample_uniform(HOME_SEEDS, np.random.default_rng(0)))
    if seeds.shape[1] != robot.n:
        raise ManifoldgenError(f"home has {seeds.shape[1]} values but the group has {robot.n} joints "
                               f"({', '.join(robot.joints)}); give one value per joint")
    past = np.maximum(robot.lower - seeds[0], seeds[0] - robot.upper)
    if home is not None and past.max() > HOME_SLACK:
        j = int(np.argmax(past))
        raise ManifoldgenError(f"home {robot.joints[j]} = {seeds[0, j]:g} is outside its limits [{robot.lower[j]:g}, "
                               f"{robot.upper[j]:g}]; give a home inside the joint limits")
    kind, m = f"{type(constraint).__module__}:{type(constraint).__name__}", len(constraint.tolerance)
    raw = constraint.residual(seeds, y)
    if not hasattr(raw, "shape"):
        raise ManifoldgenError(f"task '{name}': the residual of constraint {kind} is a {type(raw).__name__}, not an "
                               f"array of shape ({len(seeds)}, {m}); fix its residual() to return an array (numpy "
                               "in, numpy out; torch in, torch out)")
    residual = np.asarray(raw, float)
    if residual.shape != (len(seeds), m) or not np.isfinite(residual).all():
        what = (f"has shape {residual.shape}, not ({len(seeds)}, {m}) (one value per tolerance)"
                if residual.shape != (len(seeds), m) else "holds NaN or infinite values")
        raise ManifoldgenError(f"task '{name}': the residual of constraint {kind} {what}; fix its residual()")
    own = own_jacobian(constraint)  # else central differences of the numpy residual steer the home's projection
    if own:
        jacobian = np.asarray(constraint.jacobian(seeds[:1], y)[1], float)
        if jacobian.shape != (1, m, robot.n):
            raise ManifoldgenError(f"task '{name}': the jacobian of constraint {kind} has shape {jacobian.shape} for "
                                   f"one configuration, not (1, {m}, {robot.n}) (residuals x joints); fix its "
                                   "jacobian()")
    inequality = np.asarray(constraint.inequality(seeds, y), float)
    if inequality.ndim != 2 or len(inequality) != len(seeds) or not np.isfinite(inequality).all():
        what = (f"has shape {inequality.shape}, not ({len(seeds)}, p) (p inequalities per configuration, 0 for none)"
                if inequality.ndim != 2 or len(inequality) != len(seeds) else "holds NaN or infinite values")
        raise ManifoldgenError(f"task '{name}': the inequality of constraint {kind} {what}; fix its inequality()")
    res = project(constraint, seeds, y, jacobian=None if own else partial(central_difference, constraint.residual))
    if not res.converged.any():
        where = "home" if home is not None else f"{HOME_SEEDS} uniform configurations"
        raise ManifoldgenError(f"task '{name}': projecting {where} onto the constraint at condition {y.tolist()} "
                               "failed; give a home configuration closer to the manifold, or check the constraint")
    return Task(name, robot, constraint, res.q[int(np.argmax(res.converged))], y, notes, scenes)


def _home_condition(condition: Condition, value) -> np.ndarray:
    """The task's ``home_condition``: one of the condition's values or between them."""
    y = _numbers(value, "home_condition")
    if y.shape == (condition.k,) and np.any((y < condition.low - 1e-9) | (y > condition.high + 1e-9)):
        raise ManifoldgenError(f"home_condition {y.tolist()} is outside the task's condition values "
                               f"({condition.describe()}); give a home_condition inside them")
    return condition.check(y)[0]


def _numbers(value, what: str) -> np.ndarray:
    """``value`` (numbers, no strings or booleans) as a flat float array, or a clear error."""
    try:
        if not _only_numbers(value) or np.ndim(value) > 1:  # a flat list: [[0.45]] is not a condition
            raise TypeError
        numbers = np.asarray(value, float).reshape(-1)
    except (TypeError, ValueError):
        raise ManifoldgenError(f"{what} must be a flat list of numbers (no strings or booleans), got {short(value, 80)}"
                               ) from None
    if not np.isfinite(numbers).all():
        raise ManifoldgenError(f"{what} must be finite numbers, got {numbers.tolist()}")
    return numbers


def _only_numbers(value) -> bool:
    """Whether ``value`` is a number or a (nested) list of numbers: no strings, no booleans."""
    value = value.tolist() if isinstance(value, np.ndarray) else value
    if isinstance(value, (list, tuple)):
        return all(_only_numbers(v) for v in value)
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


# ---------------------------------------------------------------------- task files
def _line(text: str, key: str) -> int:
    """The 1-based line where ``key`` is set or opens a table in TOML ``text`` (0 if not found)."""
    pattern = re.compile(rf"^[ \t]*(\[\[?[ \t]*{re.escape(key)}[ \t]*\]\]?|{re.escape(key)}[ \t]*=)", re.M)
    found = pattern.search(text)
    return text.count("\n", 0, found.start()) + 1 if found else 0


def _nth_table_line(text: str, key: str, index: int) -> int:
    lines = [text.count("\n", 0, m.start()) + 1
             for m in re.finditer(rf"^[ \t]*\[\[[ \t]*{re.escape(key)}[ \t]*\]\]", text, re.M)]
    return lines[index] if index < len(lines) else 0


@file_reader
def load_task_file(path: str | Path) -> Task:
    """Read a TOML task file (see the module doc and docs/tasks.md)."""
    path = Path(path)
    if not path.is_file():
        raise ManifoldgenError(f"{not_a_file(path, 'task file')}; give a .toml task file or a built-in task name")
    data, text = read_toml_file(path, "task file")

    def where(key: str) -> str:
        line = _line(text, key)
        return f"{path}, line {line}" if line else str(path)

    unknown = [k for k in data if k not in TASK_KEYS]
    if unknown:
        raise ManifoldgenError(f"{where(unknown[0])}: unknown key '{unknown[0]}'; known keys: {', '.join(TASK_KEYS)}")
    for key, value in data.items():
        kind = TASK_TYPES[key]
        if not isinstance(value, kind) or (key == "group" and not all(isinstance(j, str) for j in value)):
            what = "a list of joint names" if key == "group" else TYPE_WORDS[kind]
            raise ManifoldgenError(f"{where(key)}: '{key}' ({TASK_KEYS[key]}) must be {what}, got {value!r}")
    for key in ("name", "robot", "constraints"):
        if key not in data:
            raise ManifoldgenError(f"{path}: missing '{key}' ({TASK_KEYS[key]}); every task file needs name, robot "
                                   "and at least one [[constraints]] table")
    if not data["name"].strip():
        raise ManifoldgenError(f"{where('name')}: 'name' ({TASK_KEYS['name']}) is empty; give the task a name, e.g. "
                               "name = \"pose\"")
    if "base_bounds" in data and not data.get("floating_base", False):
        raise ManifoldgenError(f"{where('base_bounds')}: 'base_bounds' bounds a floating base; this task's robot has "
                               "a fixed base: drop it, or set floating_base = true")
    base = path.resolve().parent
    source = str(data["robot"])
    if source.endswith(".urdf") or "/" in source:
        source = str((base / source).resolve())
    try:
        robot_obj = Robot.load(source, data.get("group"), reference=_floats_table(data.get("locked", {}), where),
                               floating_base=bool(data.get("floating_base", False)),
                               srdf=str(base / data["srdf"]) if "srdf" in data else None,
                               **({"base_bounds": data["base_bounds"]} if "base_bounds" in data else {}))
    except ManifoldgenError as exc:
        named = [k for k in ("group", "locked") if any(f"'{j}'" in str(exc) for j in data.get(k, []))]
        raise ManifoldgenError(f"{where(named[0] if named else 'robot')}: {exc}") from None
    tables = data["constraints"]
    if not isinstance(tables, list) or not tables:
        raise ManifoldgenError(f"{where('constraints')}: write each constraint as a [[constraints]] table with a 'type'")
    parts = []
    for i, table in enumerate(tables):
        try:
            for module in code_types(table):
                _not_shadowed(module.partition(":")[0], base)
            with _importable_from(base) if code_types(table) else contextlib.nullcontext():
                parts.append(build_constraint(robot_obj, table))
        except ManifoldgenError as exc:
            raise ManifoldgenError(f"{path}, line {_nth_table_line(text, 'constraints', i)}: constraint {i + 1}: "
                                   f"{exc}") from None
    constraint = parts[0] if len(parts) == 1 else ConstraintSet(parts)
    bad = next((k for k, v in data.get("scenes", {}).items() if not isinstance(v, str)), None)
    if bad is not None:
        raise ManifoldgenError(f"{where('scenes')}: scene '{bad}' must be a scene file path (a string), got "
                               f"{data['scenes'][bad]!r}")
    scenes = {str(k): (base / str(v)).resolve() for k, v in data.get("scenes", {}).items()}
    gone = next((k for k, file in scenes.items() if not file.is_file()), None)
    if gone is not None:
        file = scenes[gone]
        what = ("is a folder" if file.is_dir() else "is not a regular file (a device, pipe or socket)" if file.exists()
                else "does not exist")
        raise ManifoldgenError(f"{where('scenes')}: scene '{gone}': {file} {what} (scene paths are relative "
                               "to the task file's folder); fix the path or drop the scene")
    try:
        task = _finish(str(data["name"]), robot_obj, constraint, data.get("home"), data.get("home_condition"),
                       str(data.get("description", "")), scenes)
    except ManifoldgenError as exc:
        raise ManifoldgenError(f"{where('home_condition' if str(exc).startswith('home_condition') else 'home')}: "
                               f"{exc}") from None
    task.file = path.resolve()
    if "attached" in data:
        try:
            task.attached = _held(task, data["attached"])
        except ManifoldgenError as exc:
            raise ManifoldgenError(f"{where('attached')}: {exc}") from None
    if "planner" in data:
        try:
            task.planner = _planner_defaults(data["planner"])
        except ManifoldgenError as exc:
            raise ManifoldgenError(f"{where('planner')}: {exc}") from None
    return task


def _planner_defaults(table) -> dict:
    """The task file's ``[planner]`` table, each key a setting of one of our planners with a value of its type."""
    if not isinstance(table, dict):
        raise ManifoldgenError("'planner' must be a table of setting = value, e.g. reach = 0.2")
    known = {k: v for name in PLANNERS.names() for k, v in planner_settings(name).items()}
    values = check_settings(table, known, "planner")
    for name in PLANNERS.names():  # each value within its range, as the planners will check it
        own = {k: v for k, v in values.items() if k in planner_settings(name)}
        if own:
            PLANNERS.get(name).settings_type(**own).check()
    return values


def _held(task: Task, table) -> dict:
    """The task file's ``[attached]`` table as a held object's JSON-ready dict, refusing one that does not
    parse or that collides with the robot at the task's home (the links holding it excepted)."""
    from manifoldgen.shapes import Attached, held_checker  # coal: loaded when a task holds something

    if not isinstance(table, dict):
        raise ManifoldgenError("'attached' must be one table: type, size (box), pose {position, quaternion} in "
                               "the 'attached_to' frame, touch_links (the links holding it)")
    held = Attached.from_dict(table)
    task.robot.frame_id(held.frame)
    held.resolved_touch_links(task.robot)
    name = held.shape.name
    hits = [pair for pair in held_checker(task.robot, held).collisions(task.home) if name in pair]
    if hits:
        links = ", ".join(b if a == name else a for a, b in hits[:3])
        raise ManifoldgenError(f"the held {held.shape.type} '{name}' collides with the robot at home ({links}); "
                               "move or shrink it, or add the links that hold it to touch_links")
    return held.to_dict()


def _not_shadowed(module: str, folder: Path) -> None:
    """Refuse a task file whose folder holds ``module`` (its top-level package) when this process already imported
    a module of that name from another file: Python would reuse that one, not the task's."""
    top = module.partition(".")[0]
    loaded = getattr(sys.modules.get(top), "__file__", None)
    own = next((f for f in (folder / f"{top}.py", folder / top / "__init__.py") if f.is_file()), None)
    if loaded and own and Path(loaded).resolve() != own.resolve():
        raise ManifoldgenError(f"module {top} is already imported in this process from {loaded}, not from the task "
                               f"file's folder ({own}); rename one of the two modules, or load this task in a new "
                               "process")


@contextlib.contextmanager
def _importable_from(folder: Path):
    """Let a task file's ``module:Class`` import a module that sits in ``folder`` (the file's): the folder is
    first on ``sys.path`` only while that constraint is built, so no file there shadows a later import."""
    entry = str(folder)
    sys.path.insert(0, entry)
    try:
        yield
    finally:
        if entry in sys.path:
            sys.path.remove(entry)


def _floats_table(table, where) -> dict[str, float]:
    if not isinstance(table, dict) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                              and np.isfinite(v) for v in table.values()):
        raise ManifoldgenError(f"{where('locked')}: 'locked' must be a table of joint = finite number, got {table!r}")
    return {str(k): float(v) for k, v in table.items()}


# ---------------------------------------------------------------------- built-in tasks
@lru_cache(maxsize=None)
def builtin_tasks() -> dict[str, dict[str, Path]]:
    """Task name -> robot -> built-in task file; each name's default robot first."""
    found: dict[str, list[tuple[bool, str, Path]]] = {}
    for file in sorted(BUILTIN_DIR.glob("*.toml")):
        data = tomllib.loads(file.read_text())
        robot = str(data["robot"])  # a URDF path is known by its robot name, the file stem (as Robot.name)
        robot = Path(robot).stem if robot.endswith(".urdf") else robot
        found.setdefault(data["name"], []).append((not data.get("default", False), robot, file))
    return {name: {robot: file for _, robot, file in sorted(rows)} for name, rows in found.items()}


def is_task_file(task: str) -> bool:
    return task.endswith(".toml") or Path(task).is_file()


@lru_cache(maxsize=None)
def get_task(task: str, robot: str | None = None) -> Task:
    """A built-in task by name (for ``robot``, default: the task's default robot) or a task file."""
    if not isinstance(task, str) or not isinstance(robot, (str, type(None))):
        raise ManifoldgenError(f"a task is named by a string (and its robot by a string or None), got {task!r}, "
                               f"{robot!r}")
    if is_task_file(task):
        loaded = load_task_file(task)
        if robot is not None and robot not in (loaded.robot.name, loaded.robot.source):
            raise ManifoldgenError(f"task file {task} is for robot '{loaded.robot.name}', not '{robot}'; drop "
                                   "--robot (a task file names its robot) or edit the file's 'robot'")
        return loaded
    tasks = builtin_tasks()
    if task not in tasks and Path(task).exists():  # a folder or a device: not "unknown"
        raise ManifoldgenError(f"{not_a_file(task, 'task file')}; give a .toml task file or a built-in task name")
    if task not in tasks:
        raise unknown_name("task", task, list(tasks))
    robots = tasks[task]
    robot = next(iter(robots)) if robot is None else robot
    if robot not in robots:
        resolve_robot(robot)  # an unknown robot is reported as such
        raise ManifoldgenError(f"task '{task}' is not defined for robot '{robot}'; robots with it: "
                               f"{', '.join(robots)}; or write a task file for it (see docs/tasks.md)")
    return load_task_file(robots[robot])


__all__ = ["Task", "builtin_tasks", "code_types", "get_task", "load_task_file", "task_from_meta",
           "task_from_spec"]
