"""One planning query end to end, as ``manifoldgen plan`` runs it: task + scene + sampler spec
+ planner -> a validated path file (``path (K, n)`` + ``meta``) and its picture.

The path file's ``meta`` holds everything an outside checker needs with pinocchio and coal
alone: the robot, joints, locked joints, the constraint specification, the condition ``y``
of the query, and the scene (obstacles with world poses; the held tool with its frame,
placement and touch links).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
from dataclasses import asdict
from pathlib import Path

import numpy as np

from manifoldgen.dataset import check_copies
from manifoldgen.errors import ManifoldgenError, did_you_mean, listed, short
from manifoldgen.io import check_output_path, output_lock, save_npz
from manifoldgen.json_values import finite, text, whole
from manifoldgen.planning import PLANNERS, planner_settings
from manifoldgen.planning.base import SMOOTH_SHORTCUTS, Planner, check_time_limit
from manifoldgen.planning.local import DEFAULT_LOCAL, LOCAL_PLANNERS
from manifoldgen.planning.result import PlanResult, path_length
from manifoldgen.runtime import MAX_SEED, check_seed
from manifoldgen.scene import Scene
from manifoldgen.settings import check_settings
from manifoldgen.space import RESOLUTION_RANGE, ConstrainedSpace
from manifoldgen.specs import make_sampler
from manifoldgen.tasks import Task

PATH_FORMAT_VERSION = 2  # 2: meta["task"] holds the full task spec
PATH_KEYS = ("task", "robot", "joints", "locked", "floating_base", "constraint", "tolerance", "condition",
             "format_version", "kind", "condition_names", "scene_name", "scene", "start", "goal", "planner",
             "planner_settings", "sampler", "local", "seed", "time_limit", "smoothed", "result", "validation")
# a path file's meta: the task's (Task.meta), the query's (query_meta) and the planner's (plan_query)
ENDPOINT_TOLERANCE = 1e-6  # rad: how far path[0] and path[-1] may lie from the recorded start and goal

# the kinds of a path file's meta values besides the task's and the query's, as plan_query writes them: (whether a
# value fits, what it must be)
TEXT = (text, "a string")
FLAG = (lambda v: isinstance(v, bool), "true or false")
OBJECT = (lambda v: isinstance(v, dict), "an object")
COUNT = (whole, "a whole number >= 0")
SEGMENT = (lambda v: whole(v, -1), "a whole number >= -1")
SEED = (lambda v: whole(v, 0, MAX_SEED), f"a whole number from 0 to {MAX_SEED}")
POSITIVE = (lambda v: finite(v) and v > 0, "a finite number > 0")
AMOUNT = (lambda v: finite(v, 0), "a finite number >= 0")
TRUE = (lambda v: v is True, "true (plan writes only solved, checked paths)")
LOCAL = (lambda v: text(v) and v in LOCAL_PLANNERS, f"a local planner ({', '.join(LOCAL_PLANNERS)})")
RESOLUTION = (lambda v: finite(v, *RESOLUTION_RANGE), "a number from {:g} to {:g} (rad)".format(*RESOLUTION_RANGE))
VALUE_KINDS = {"scene_name": TEXT, "planner": TEXT, "sampler": TEXT, "local": LOCAL, "seed": SEED,
               "time_limit": POSITIVE, "smoothed": FLAG, "planner_settings": OBJECT, "result": OBJECT,
               "validation": OBJECT}
NESTED_KINDS = {"result": {"solved": TRUE, "time_s": AMOUNT, "iterations": COUNT, "samples_drawn": COUNT,
                           "projections": COUNT, "planner": TEXT, "length": AMOUNT, "waypoints": COUNT,
                           "extras": OBJECT},
                "validation": {"valid": TRUE, "worst_violation": AMOUNT, "reason": TEXT, "segment": SEGMENT,
                               "states_checked": COUNT, "resolution": RESOLUTION}}


def get_planner(name: str) -> type[Planner]:
    """The planner class registered as ``name`` (clear error listing the known ones)."""
    return PLANNERS.get(name)


def run_query(task: Task, scene: Scene, sampler: str, planner: str, *, seed: int, time_limit: float,
              local: str = DEFAULT_LOCAL, smooth: bool = False, settings: dict | None = None,
              roadmap: str | Path | None = None) -> tuple[PlanResult, dict]:
    """Plan the scene's query with the planner's ``settings`` (field -> value; see
    :func:`manifoldgen.planning.planner_settings`); returns the result (path re-validated, optionally smoothed)
    and the path file's ``meta`` (``meta["validation"]`` holds the check and the resolution it used). ``roadmap``:
    a roadmap file the query is routed through first and that keeps its path (see :func:`plan_query`)."""
    check_time_limit(time_limit)  # before the space is built
    seed = check_seed(seed)
    get_planner(planner)  # an unknown planner is refused before the space is built
    y = task.condition.check(scene.condition)[0]
    space = ConstrainedSpace(task.constraint, y, scene.checker(task.robot))
    return plan_query(task, scene, space, make_sampler(sampler, space, seed), sampler, planner, seed=seed,
                      time_limit=time_limit, local=local, smooth=smooth, settings=settings, roadmap=roadmap)


def plan_query(task: Task, scene: Scene, space: ConstrainedSpace, sampler, label: str, planner: str, *, seed: int,
               time_limit: float, local: str = DEFAULT_LOCAL, smooth: bool = False, settings: dict | None = None,
               roadmap: str | Path | None = None) -> tuple[PlanResult, dict]:
    """:func:`run_query` with a sampler object made for ``space`` (the scene's condition and checker); ``label``
    names the sampler in the path file's ``meta``. With ``roadmap`` (a file) the planner reuses its paths: the
    roadmap saved there (when the file exists; refused when made for another query space) is searched first, and
    after a solved query it is written back (atomic) with the new path, holding only what passed the dense check
    (what was read from the file and fails is dropped, counted in ``result.extras["roadmap"]["dropped"]``); the
    file is locked meanwhile. A link is written through: its path is resolved once, before the lock."""
    planner_type = get_planner(planner)
    values = task_settings(task, planner, settings)
    if smooth:  # shortened within the query, by the planner (the core's search in the core)
        values.setdefault("shortcut", SMOOTH_SHORTCUTS)
    if roadmap is not None:
        values["reuse"], roadmap = True, Path(roadmap).resolve()
    solver = planner_type(space, sampler, local=local, seed=seed, settings=planner_type.settings_type(**values))
    with output_lock(roadmap, "roadmap") if roadmap is not None else contextlib.nullcontext():
        if roadmap is not None:
            about = roadmap_meta(task, scene, space)
            if Path(roadmap).exists():
                solver.load_roadmap(roadmap, about)
        result = solver.solve(scene.start, scene.goal, time_limit)
        held = solver.roadmap
        if roadmap is not None and result.solved and not held.grown:
            held.check_lone_nodes()  # cheap; what the file holds besides is checked where a route takes it
        written = roadmap is not None and result.solved and (held.grown or any(held.dropped.values())
                                                             or not roadmap.exists())
        if written:  # a query that changed nothing leaves the file as it is (and skips the save's check of edges)
            held.save(roadmap, about)
        if roadmap is not None:  # the roadmap's counts after the save's check
            result.extras["roadmap"].update(nodes=len(solver.roadmap), edges=solver.roadmap.edge_count(),
                                            dropped=dict(solver.roadmap.dropped), written=written)
    report = space.validate_path(result.path) if result.solved else None
    if report is not None and not report.valid:  # the planners only return validated paths
        raise RuntimeError(f"internal error: a returned path failed validation: {report.reason}")
    meta = {**query_meta(task, scene, space.y),
            "planner": planner, "planner_settings": asdict(solver.settings), "sampler": label,
            "local": solver.local.name, "seed": seed,
            "time_limit": time_limit, "smoothed": smooth, "result": result.to_dict(),
            "validation": report.to_dict() if report else unsolved_validation(space.settings.resolution)}
    return result, meta


def query_meta(task: Task, scene: Scene, y: np.ndarray) -> dict:
    """What a path file's ``meta`` says of the query whoever plans it: the task, the condition ``y (k,)``, the
    scene, start and goal (the planner's part and the check's are added by the caller)."""
    return {**task.meta(), "format_version": PATH_FORMAT_VERSION, "kind": "path",
            "condition": np.asarray(y, float).tolist(), "condition_names": list(task.condition.names),
            "scene_name": scene.name, "scene": scene.to_meta(task.robot),
            "start": np.asarray(scene.start, float).tolist(), "goal": np.asarray(scene.goal, float).tolist()}


def roadmap_meta(task: Task, scene: Scene, space: ConstrainedSpace) -> dict:
    """A roadmap file's ``meta`` for queries in ``space`` (the task at the scene's condition, with its obstacles): a
    path file's task, condition and scene (no start or goal), and the keys that a roadmap loaded for a query must
    match (:data:`~manifoldgen.planning.roadmap.IDENTITY`): the robot's identity, the base bounds, the scene's
    fingerprint and the dense check's resolution. :meth:`~manifoldgen.planning.roadmap.Roadmap.save` adds the
    format, kind and reach."""
    query = query_meta(task, scene, space.y)
    objects = json.dumps(query["scene"], sort_keys=True, separators=(",", ":"))
    return {**{k: v for k, v in query.items() if k not in ("format_version", "kind", "start", "goal")},
            "robot_identity": task.robot.identity, "base_bounds": task.robot.base_bounds.tolist(),
            "scene_sha256": hashlib.sha256(objects.encode()).hexdigest(), "resolution": space.settings.resolution}


def unsolved_validation(resolution: float) -> dict:
    """``meta["validation"]`` of an unsolved query: a checked path's keys, ``valid`` False, no state checked
    (``worst_violation`` 0.0, the check's starting value; plain JSON, no NaN)."""
    return {"valid": False, "worst_violation": 0.0, "reason": "not solved: no path to check", "segment": -1,
            "states_checked": 0, "resolution": resolution}


def task_settings(task: Task, planner: str, settings: dict | None = None) -> dict:
    """``planner``'s settings for ``task``: the task file's ``[planner]`` defaults it takes, then ``settings``."""
    known = planner_settings(planner)
    return {**{k: v for k, v in task.planner.items() if k in known}, **(settings or {})}


def read_path_file(path_file: str | Path, task: Task | None = None, *, trust_code: bool = False,
                   ) -> tuple[dict, np.ndarray, Task]:
    """A path file, checked whole before anything uses it: its ``meta``, ``path (K, n)`` (K >= 1 finite
    states) and the task rebuilt from the meta (``task``, ``trust_code``: see
    :func:`~manifoldgen.tasks.task_from_meta`). Refused in one line: another kind of file, another format
    version, an array or a meta key a path file does not hold, an empty or malformed path, a path that does not
    fit the task's joints (their number and names), a missing condition, a first or last state that is not the
    recorded ``start`` or ``goal``."""
    from manifoldgen.io import load_npz
    from manifoldgen.tasks import task_from_meta

    meta, arrays = load_npz(path_file, (), "path file")
    if "path" not in arrays or meta.get("kind", "path") != "path":
        raise ManifoldgenError(f"{path_file} is not a path file (no 'path' array, or its meta says kind "
                               f"{short(meta.get('kind'))}); give a file written by `manifoldgen plan`")
    if meta.get("format_version") != PATH_FORMAT_VERSION:
        raise ManifoldgenError(f"{path_file}: path format {short(meta.get('format_version'))} is not the one this "
                               f"version reads ({PATH_FORMAT_VERSION}); plan the query again")
    _check_contents(path_file, meta, arrays)
    _check_values(path_file, meta)
    path = arrays["path"]
    if path.dtype != np.float64 or path.ndim != 2 or len(path) == 0 or not np.isfinite(path).all():
        raise ManifoldgenError(f"{path_file}: 'path' must be a non-empty (K, n) float64 array of finite numbers (as "
                               f"`plan` writes it), got {path.dtype} of shape {path.shape}; plan the query again")
    path = np.asarray(path, float)
    task = task_from_meta(meta, task=task, trust_code=trust_code, what=str(path_file))
    if path.shape[1] != task.robot.n:
        raise ManifoldgenError(f"{path_file}: its states have {path.shape[1]} coordinates, {task.robot.name}'s "
                               f"{task.name} task has {task.robot.n} joints")
    _check_joints(path_file, meta.get("joints"), task)
    if "condition_names" in meta and meta["condition_names"] != list(task.condition.names):
        raise ManifoldgenError(f"{path_file}: meta 'condition_names' {short(meta['condition_names'])} are not its "
                               f"task's {short(list(task.condition.names))}; the file was edited: plan the query "
                               "again")
    if meta.get("tolerance") != task.constraint.tolerance.tolist():  # what an outside checker checks against
        raise ManifoldgenError(f"{path_file}: meta 'tolerance' {short(meta.get('tolerance'))} is not its task's "
                               f"{short(task.constraint.tolerance.tolist())}; the file was edited: plan the query "
                               "again")
    if meta.get("robot") != task.robot.name:  # an outside checker reads this name: it must be the task's robot
        raise ManifoldgenError(f"{path_file}: meta 'robot' {short(meta.get('robot'))} is not its task's robot "
                               f"{task.robot.name!r}; the file was edited: plan the query again")
    try:
        y = np.asarray(meta.get("condition", []), dtype=float).reshape(-1)
    except (TypeError, ValueError):
        y = np.array([np.nan])
    if not isinstance(meta.get("condition"), list) or len(y) != task.condition.k or not np.isfinite(y).all():
        raise ManifoldgenError(f"{path_file}: meta 'condition' must be {task.condition.k} finite numbers, got "
                               f"{short(meta.get('condition'))}")
    _check_ends(path_file, meta, path)
    said = meta.get("result", {})
    if said.get("waypoints", len(path)) != len(path) or not math.isclose(
            said.get("length", path_length(path)), path_length(path), rel_tol=1e-9, abs_tol=1e-9):
        raise ManifoldgenError(f"{path_file}: meta 'result' gives {said.get('waypoints')} waypoints of length "
                               f"{said.get('length')}, but the path has {len(path)} of length {path_length(path):.6g}; "
                               "the file was edited: plan the query again")
    return meta, path, task


def _check_contents(path_file: str | Path, meta: dict, arrays: dict) -> None:
    """Refuse an array besides ``path`` or a meta key besides :data:`PATH_KEYS`: no reader checks what they say."""
    extra = sorted(name for name in arrays if name != "path")
    if extra:
        raise ManifoldgenError(f"{path_file}: unknown array {listed([short(name) for name in extra])}; a path file "
                               "holds only 'path' and 'meta': remove it or plan the query again")
    unknown = sorted(key for key in meta if key not in PATH_KEYS)
    if unknown:
        raise ManifoldgenError(f"{path_file}: unknown meta key {short(unknown[0])}"
                               f"{did_you_mean(unknown[0], PATH_KEYS)}; a path file's meta holds only the keys of "
                               "docs/file-formats.md (Path files): remove it or plan the query again")


def _check_values(path_file: str | Path, meta: dict) -> None:
    """Refuse a missing ``kind``, top-level copies of the task that contradict ``meta["task"]``
    (:func:`~manifoldgen.dataset.check_copies`), a planner's meta value (:data:`VALUE_KINDS`, :data:`NESTED_KINDS`,
    the planner's settings) of the wrong kind or range, or an unknown key inside ``result``, ``validation`` or
    ``planner_settings``, naming it."""
    def refuse(key: str, why: str):
        raise ManifoldgenError(f"{path_file}: meta '{key}' {why}; the file was edited: plan the query again")

    if "kind" not in meta:
        refuse("kind", 'is missing (plan writes "path")')
    check_copies(meta, lambda why: ManifoldgenError(f"{path_file}: meta {why}; the file was edited: plan the query "
                                                    "again"))

    for key, (fits, what) in VALUE_KINDS.items():
        if key in meta and not fits(meta[key]):
            refuse(key, f"must be {what}, got {short(meta[key])}")
    for key, kinds in NESTED_KINDS.items():
        for name, value in meta.get(key, {}).items():
            if name not in kinds:
                refuse(f"{key}.{name}", f"is not a key of '{key}' (known: {', '.join(kinds)})")
            fits, what = kinds[name]
            if not fits(value):
                refuse(f"{key}.{name}", f"must be {what}, got {short(value)}")
    if "planner_settings" in meta:
        planner = meta.get("planner")
        if planner not in PLANNERS.names():
            refuse("planner", f"{short(planner)} is not a planner (known: {', '.join(PLANNERS.names())})")
        known = planner_settings(planner)
        unknown = next((name for name in meta["planner_settings"] if name not in known), None)
        if unknown is not None:
            refuse(f"planner_settings.{unknown}",
                   f"is not a setting of planner {planner}{did_you_mean(unknown, known)}")
        try:  # the kinds, then the ranges the planner itself takes
            settings = check_settings(meta["planner_settings"], known, f"planner {planner}")
            PLANNERS.get(planner).settings_type(**settings).check()
        except ManifoldgenError as exc:
            refuse("planner_settings", f"holds a wrong value ({exc})")


def _check_joints(path_file: str | Path, joints, task: Task) -> None:
    """Refuse a path file whose meta ``joints`` (the names of its columns, as an outside checker reads them) are
    not its task's, naming the first few columns that differ."""
    wanted = task.robot.joints
    if joints == wanted:
        return
    if isinstance(joints, list) and len(joints) == len(wanted):
        shown = listed([f"column {i} {short(made)} vs {name}" for i, (made, name) in enumerate(zip(joints, wanted))
                        if made != name])
    else:
        shown = f"{short(joints)} vs {len(wanted)} names"
    raise ManifoldgenError(f"{path_file}: meta 'joints' are not its {task.name} task's joints: {shown}; the file was "
                           "edited: plan the query again")


def _check_ends(path_file: str | Path, meta: dict, path: np.ndarray) -> None:
    """Refuse a path whose first or last state lies more than :data:`ENDPOINT_TOLERANCE` from the recorded
    ``start`` or ``goal`` (where the meta records them), as an outside checker does."""
    for key, state, verb in (("start", path[0], "start"), ("goal", path[-1], "end")):
        if key not in meta:
            continue
        try:
            recorded = np.asarray(meta[key], dtype=float)
        except (TypeError, ValueError):
            recorded = np.array([np.nan])
        if recorded.shape != state.shape or not np.isfinite(recorded).all():
            raise ManifoldgenError(f"{path_file}: meta '{key}' must be {len(state)} finite numbers, got "
                                   f"{short(meta[key])}; the file was edited: plan the query again")
        gap = float(np.abs(recorded - state).max())
        if gap > ENDPOINT_TOLERANCE:
            raise ManifoldgenError(f"{path_file}: the path does not {verb} at the recorded {key} (meta '{key}'): "
                                   f"{gap:.3g} rad apart; the file was edited: plan the query again")


def save_path(output: str | Path, result: PlanResult, meta: dict, what: str = "-o") -> None:
    """Write the path file (atomic): ``path (K, n)`` and ``meta`` (a JSON string); ``what`` names ``output`` in a
    refusal (the command line's option, the API's argument)."""
    save_npz(check_output_path(output, what=what, kind="path"), meta, path=result.path)
