"""Planning experiments (the paper's Tables II and III): every method, same query, same seeds.

A *method* is written ``[LABEL=]PLANNER[:LOCAL][@SAMPLER]``:

- ``PLANNER``: one of :data:`manifoldgen.planning.PLANNERS` (``rrtconnect``, ``cbirrt``, ...)
  with a ``LOCAL`` planner (``auto`` by default, ``interpolate`` or ``project``), or an OMPL baseline
  ``ompl-SPACE-PLANNER`` (e.g. ``ompl-projected-rrtconnect``, ``ompl-atlas-prm``; see
  :mod:`manifoldgen.ompl_bridge`), or the C++ OMPL baseline ``ompl-native-SPACE`` (RRTConnect in
  ``projected``, ``atlas`` or ``tangent``, the callbacks compiled; see :mod:`manifoldgen.ompl_native`);
- ``SAMPLER``: a sampler spec for :func:`manifoldgen.specs.make_sampler` (``cvae:DIR``,
  ``pg:DATASET.npz``, ``project``, ``uniform``); ``pg`` alone means a PG dataset of
  ``pg_rows`` configurations at the scene's condition, collected once into the output folder;
  ``blind`` means uniform samples in a space of joint limits and collisions only, ignoring the task
  constraint (the balance-blind baseline); ``feet-only`` means uniform seeds projected onto the
  balance constraint without its CoM inequality (blind to the centre of mass only). Our planners
  default to ``uniform``; OMPL's tree planners take no sampler.

For a balance task every solved path's static stability is recorded too (``stability``: the share of
states whose centre of mass leaves the support polygon, feet drift; :mod:`manifoldgen.stability`).

Run ``r`` of every method uses seed ``seed + r`` for its sampler and planner. Runs execute in
worker processes (each builds its own robot, checker, sampler and planner, with one torch
thread); each finished run is appended to ``runs.jsonl`` at once, so an interrupted benchmark
keeps its runs and ``resume=True`` skips them. A record holds the run's CPU time (``cpu_s``: this
process's; for the C++ OMPL baseline, its program's plus our dense check of its paths, with the harness
around it, writing the problem and exchanging paths, apart in ``harness_cpu_s``) and its operation counts (``ops``, see :func:`operations`).
Every solved path is re-validated here, independently of the planner, by the space's dense check
(``ValidationSettings.resolution``); a run counts as solved only when that check passes and the
planner answered within the time limit. ``results.md`` and box plots summarise the records
(:mod:`manifoldgen.bench.report`).

With a :class:`~manifoldgen.cluster.Cluster`, every run is a task on the cluster instead: its CPU time is
measured on the worker, and its record adds the ``host`` and Ray ``node`` it ran on; the driver appends the
records as they arrive. Inputs (models, datasets, scene and task files) must be at the same path on every node.
"""

from __future__ import annotations

import json
import math
import multiprocessing
import os
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field, fields
from functools import lru_cache
from pathlib import Path

import numpy as np

from manifoldgen.bench.report import MethodSummary, write_report
from manifoldgen.cluster import Cluster, connect
from manifoldgen.data import MAX_ROWS
from manifoldgen.errors import ManifoldgenError, short
from manifoldgen.io import atomic_write_text, check_name, check_own_folder, locks_output
from manifoldgen.progress import progress_bar
from manifoldgen.runtime import check_seed

RUNS_FILE = "runs.jsonl"
CONFIG_FILE = "config.json"
PROBLEM_FILE = "problem.json"  # the path meta every run's path shares: an outside checker rechecks each from it
BENCH_MARKERS = (CONFIG_FILE, RUNS_FILE)  # a folder holding one of them is a benchmark's
OUTPUT_FILES = (RUNS_FILE, CONFIG_FILE, PROBLEM_FILE, "results.md", "time.png", "length.png")
PAPER_LIMITS = {"wall": {"runs": 1000, "time_limit": 200.0}, "maze": {"runs": 100, "time_limit": 200.0}}
OTHER_LIMITS = {"runs": 20, "time_limit": 30.0}  # any other task's scene
OMPL_PREFIX = "ompl-"
NATIVE_PREFIX = "ompl-native-"
BLIND = "blind"  # the sampler spec of the balance-blind baseline (see manifoldgen.stability.blind_space)
FEET_ONLY = "feet-only"  # the CoM-blind baseline: feet kept, CoM ignored (manifoldgen.stability.feet_only_space)


@dataclass(frozen=True)
class Method:
    """A parsed method: ``label`` names it in tables; ``spec`` is the text it came from."""

    label: str
    planner: str
    local: str
    sampler: str | None
    spec: str

    @property
    def is_ompl(self) -> bool:
        return self.planner.startswith(OMPL_PREFIX)

    @classmethod
    def parse(cls, text: str) -> Method:
        text = text.strip()
        label, _, body = text.partition("=") if "=" in text.split("@")[0] else ("", "", text)
        shown = text if len(text) <= 60 else text[:57] + "..."  # how messages name the method
        head, at, sampler = body.partition("@")
        planner, colon, local = head.partition(":")
        if (at and not sampler) or (colon and not local):
            missing = "sampler after @" if at and not sampler else "local planner after :"
            raise ManifoldgenError(f"method '{shown}' names no {missing}; write [LABEL=]PLANNER[:LOCAL][@SAMPLER] or "
                                   "leave out the mark")
        if not planner:
            raise ManifoldgenError(f"method '{shown}' names no planner; write [LABEL=]PLANNER[:LOCAL][@SAMPLER], "
                                   "e.g. rrtconnect:interpolate@cvae:models/cvae or ompl-projected-rrtconnect")
        if planner.startswith(NATIVE_PREFIX):
            from manifoldgen.ompl_native import SPACES as NATIVE_SPACES
            if planner[len(NATIVE_PREFIX):] not in NATIVE_SPACES or local or sampler:
                raise ManifoldgenError(f"method '{shown}': the C++ OMPL methods are ompl-native-SPACE with SPACE in "
                                       f"{', '.join(NATIVE_SPACES)}, without a local planner or sampler")
        elif planner.startswith(OMPL_PREFIX):
            from manifoldgen.ompl_bridge import PLANNERS as OMPL_PLANNERS, SPACES
            parts = planner[len(OMPL_PREFIX):].split("-")
            if len(parts) != 2 or parts[0] not in SPACES or parts[1] not in OMPL_PLANNERS:
                raise ManifoldgenError(f"method '{shown}': OMPL methods are ompl-SPACE-PLANNER with SPACE in "
                                       f"{', '.join(SPACES)} and PLANNER in {', '.join(OMPL_PLANNERS)}")
            if local:
                raise ManifoldgenError(f"method '{shown}': OMPL methods take no local planner (drop ':{local}')")
            local = ""
        else:
            from manifoldgen.planning import DEFAULT_LOCAL, LOCAL_PLANNERS, PLANNERS
            if planner not in PLANNERS.names():
                raise ManifoldgenError(f"method '{shown}': unknown planner '{planner}'; known: "
                                       f"{', '.join(PLANNERS.names())}, or ompl-SPACE-PLANNER")
            local = local or DEFAULT_LOCAL
            if local not in LOCAL_PLANNERS:
                raise ManifoldgenError(f"method '{shown}': unknown local planner '{local}'; known: "
                                       f"{', '.join(LOCAL_PLANNERS)}")
            sampler = sampler or "uniform"
        label = check_name(label or _default_label(planner, local, sampler or None), f"method '{shown}': label",
                           "name the method LABEL=... with a plain LABEL")
        return cls(label, planner, local, sampler or None, text)

    def resolved(self, sampler: str | None) -> Method:
        """The same method with another sampler spec (e.g. ``pg`` given its dataset path)."""
        return Method(self.label, self.planner, self.local, sampler, self.spec)


def _default_label(planner: str, local: str, sampler: str | None) -> str:
    from manifoldgen.planning import DEFAULT_LOCAL
    label = planner + (f":{local}" if local and local != DEFAULT_LOCAL else "")
    if sampler:
        kind, _, path = sampler.partition(":")
        label += f"@{kind}" + (f":{Path(path).name}" if path else "")
    return label


def default_methods(models: list[str | Path] | None = None) -> list[str]:
    """Each learned model (default: the shipped one, when present) with each local planner, PG,
    CBiRRT, OMPL's three constrained spaces with RRTConnect, and uniform rejection sampling."""
    from manifoldgen.models import open_model, pretrained_model_dir
    from manifoldgen.planning import PLANNERS
    if models is None:
        try:
            models = [pretrained_model_dir()]
        except ManifoldgenError:
            models = []
    methods = []
    for model in models:
        if not (Path(model) / "model.json").is_file():
            raise ManifoldgenError(f"no trained model at '{model}' (model.json missing); fix the path")
        kind = open_model(model).name
        name = kind if len(models) == 1 else f"{kind}-{Path(model).name}"
        methods += [f"{name}=rrtconnect:interpolate@{kind}:{model}",
                    f"{name}-project=rrtconnect:project@{kind}:{model}"]
    methods += ["pg=rrtconnect:interpolate@pg"]
    if "cbirrt" in PLANNERS.names():
        methods += ["cbirrt=cbirrt:project@uniform"]
    methods += ["ompl-projected=ompl-projected-rrtconnect", "ompl-atlas=ompl-atlas-rrtconnect",
                "ompl-tangent=ompl-tangent-rrtconnect", "uniform=rrtconnect:interpolate@uniform"]
    return methods


def default_baseline(methods: list[str]) -> str | None:
    """The label of the first OMPL ProjectedStateSpace + RRTConnect method, the speed-up reference."""
    return next((m.label for m in map(Method.parse, methods) if m.planner == "ompl-projected-rrtconnect"), None)


@dataclass(frozen=True)
class Experiment:
    """What every run shares: the task, the scene (named or a JSON file) and the limits."""

    scene: str
    task: str = "pose"
    robot: str = "panda"
    time_limit: float = 200.0
    seed: int = 0
    resolution: float = 0.05
    planner_settings: dict = field(default_factory=dict)  # our planners' settings (each takes those it has)
    physics: bool = False  # execute every solved path in MuJoCo (balance tasks; manifoldgen.physics)

    def to_dict(self) -> dict:
        return asdict(self)


@lru_cache(maxsize=None)
def _scene(task: str, robot: str, scene: str):
    """The task and its scene with end-effector targets solved, once per worker process (solving a
    whole-body target projects hundreds of seeds; the answer depends on nothing else)."""
    from manifoldgen.scene import get_scene
    from manifoldgen.tasks import get_task

    task_obj = get_task(task, robot)
    return task_obj, get_scene(task_obj, scene)


def problem_meta(experiment: Experiment) -> dict:
    """What a path file's ``meta`` holds about the query (:func:`manifoldgen.query.plan_query`), shared by every
    run of the benchmark: the task (its constraint, whoever planned: the blind baselines' paths are judged
    against it too), condition, scene, start, goal and the dense check's resolution. With a record's ``path``
    it is a path file's content (``examples/check_path.py FOLDER`` rechecks every run that way)."""
    from manifoldgen.query import query_meta
    from manifoldgen.space import ValidationSettings

    task, scene = _scene(experiment.task, experiment.robot, experiment.scene)
    return {**query_meta(task, scene, scene.condition), "validation": {"resolution": ValidationSettings.resolution}}


def method_space(experiment: Experiment, sampler: str | None):
    """The space a method with ``sampler`` plans in, whose dense check judges its paths: limits and collisions
    only (``blind``), the feet without the centre of mass (``feet-only``), else the task's constraint."""
    from manifoldgen.space import ConstrainedSpace

    task, scene = _scene(experiment.task, experiment.robot, experiment.scene)
    if sampler == BLIND:
        from manifoldgen.stability import blind_space
        return blind_space(task.robot, scene.checker(task.robot))
    if sampler == FEET_ONLY:
        from manifoldgen.stability import feet_only_space
        return feet_only_space(task.constraint, scene.condition, scene.checker(task.robot))
    return ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))


def build(experiment: Experiment, method: Method, seed: int):
    """(planner, scene, space) for one run, built from scratch (the scene's solved query is reused)."""
    from manifoldgen.specs import make_sampler

    task, scene = _scene(experiment.task, experiment.robot, experiment.scene)
    if method.sampler == BLIND and (method.is_ompl or method.local != "direct"):
        raise ManifoldgenError(f"method '{method.spec}': the blind baseline has no constraint to walk on; "
                               "give one of our planners with straight segments, e.g. rrtconnect:direct@blind")
    space = method_space(experiment, method.sampler)
    if method.sampler == BLIND:  # the balance-blind baseline: uniform samples, limits and collisions only
        sampler = make_sampler("uniform", space, seed)
    elif method.sampler == FEET_ONLY:  # blind to the centre of mass only: feet kept, uniform seeds projected
        sampler = make_sampler("project", space, seed)
    else:
        sampler = None if method.sampler is None else make_sampler(method.sampler, space, seed)
    if method.planner.startswith(NATIVE_PREFIX):
        from manifoldgen.ompl_native import NativeOmplPlanner
        from manifoldgen.ompl_settings import OmplSettings
        from manifoldgen.planning import RRTConnectSettings
        shared = {**task.planner, **experiment.planner_settings}  # checks and shortcuts, and OMPL's ompl_KEY
        planner = NativeOmplPlanner(space, ompl_space=method.planner[len(NATIVE_PREFIX):],
                                    resolution=experiment.resolution, seed=seed,
                                    settings=OmplSettings.from_benchmark(shared),
                                    spheres=bool(shared.get("spheres", RRTConnectSettings.spheres)))
    elif method.is_ompl:
        from manifoldgen.ompl_bridge import OmplPlanner
        from manifoldgen.ompl_settings import OmplSettings
        ompl_space, planner_name = method.planner[len(OMPL_PREFIX):].split("-")
        planner = OmplPlanner(space, sampler, ompl_space=ompl_space, planner=planner_name,
                              resolution=experiment.resolution, seed=seed,
                              settings=OmplSettings.from_benchmark(experiment.planner_settings))
    else:
        from manifoldgen.planning import PLANNERS
        cls = PLANNERS.get(method.planner)
        known = {f.name for f in fields(cls.settings_type)}
        values = {"resolution": experiment.resolution, **{k: v for k, v in task.planner.items() if k in known},
                  **{k: v for k, v in experiment.planner_settings.items() if k in known}}
        planner = cls(space, sampler, local=method.local, seed=seed, settings=cls.settings_type(**values))
    return planner, scene, space


def operations(result, before: dict, after: dict) -> dict:
    """What a solve cost, counted at the source: ``fk`` configurations whose constraint kinematics
    was computed (residual, or residual and Jacobian), ``jacobians``, ``projection_steps`` (Newton /
    Levenberg-Marquardt iterations over all rows), ``collision_checks`` (configurations checked for
    collision, robot-robot and robot-scene pairs together in one broad phase, each with its own FK of
    every link), ``samples`` (configurations drawn from our sampler, or by the C++ baseline's OMPL
    sampler; the Python-callback OMPL methods' own samples are not counted), ``nodes`` (tree or roadmap
    vertices). ``before`` / ``after``: the space's :meth:`~manifoldgen.space.ConstrainedSpace.counts`
    around the solve; the OMPL baselines add what their own callbacks counted (OMPL's projections are
    Newton steps, one Jacobian each)."""
    d = {k: after[k] - before[k] for k in ("evaluations", "jacobians", "projection_steps", "collision_checks")}
    x = result.extras
    native = x.get("native_ops", {})
    newton = x.get("newton_steps", 0) + native.get("jacobians", 0)
    nodes = x.get("vertices", sum(x.get("nodes", [])) or x.get("roadmap", {}).get("nodes", 0))
    return {"fk": d["evaluations"] + d["jacobians"] + x.get("function_evals", 0) + x.get("newton_steps", 0)
            + native.get("fk", 0),
            "jacobians": d["jacobians"] + newton, "projection_steps": d["projection_steps"] + newton,
            "collision_checks": d["collision_checks"] + native.get("collision_checks", 0),
            "samples": int(result.samples_drawn) + native.get("samples", 0), "nodes": int(nodes)}


def run_once(experiment: Experiment, method: Method, run: int) -> dict:
    """One run of ``method`` (seed ``experiment.seed + run``) as a JSON-ready record."""
    seed = experiment.seed + run
    record = {"method": method.label, "spec": method.spec, "run": run, "seed": seed, "scene": experiment.scene,
              "time_limit": experiment.time_limit}
    began = time.perf_counter()
    try:
        planner, scene, space = build(experiment, method, seed)
        record["build_s"] = time.perf_counter() - began
        cpu, before = time.process_time(), space.counts()
        result = planner.solve(scene.start, scene.goal, experiment.time_limit)
        cpu = time.process_time() - cpu  # this process's CPU (robust to other load)
        if "native_cpu_s" in result.extras:  # the C++ OMPL baseline: its program's CPU plus our dense check of its
            # paths; the harness around it (writing the problem, starting the program, reading paths) apart
            record["harness_cpu_s"] = cpu - result.extras["dense_cpu_s"]
            cpu = result.extras["native_cpu_s"] + result.extras["dense_cpu_s"]
        record["cpu_s"] = cpu
        record["ops"] = operations(result, before, space.counts())
    except ManifoldgenError as exc:
        return {**record, "solved": False, "planner_solved": False, "time_s": experiment.time_limit,
                "iterations": 0, "samples_drawn": 0, "projections": 0, "length": 0.0, "waypoints": 0,
                "valid": False, "worst_violation": float("nan"), "reason": "", "error": str(exc)}
    report = space.validate_path(result.path) if result.solved else None
    summary = result.to_dict()
    stability = _stability(experiment, result.path) if result.solved else None
    physics = _physics(experiment, result.path) if stability and experiment.physics else None
    late = result.time_s > experiment.time_limit  # a planner may overrun its deadline inside one step
    return {**record, "solved": bool(result.solved and report.valid and not late),
            "planner_solved": bool(result.solved), "late": bool(late),
            "time_s": summary["time_s"], "iterations": summary["iterations"],
            "samples_drawn": summary["samples_drawn"], "projections": summary["projections"],
            "length": summary["length"], "waypoints": summary["waypoints"], "planner": summary["planner"],
            "valid": bool(report.valid) if report else False,
            "worst_violation": report.worst_violation if report else float("nan"),
            "reason": report.reason if report else "", "why": result.why(), "extras": summary["extras"],
            **({"stability": stability} if stability else {}),
            **({"physics": physics} if physics else {}),
            **({"path": result.path.tolist()} if result.solved else {})}  # every path, to recheck outside


def _stability(experiment: Experiment, path: np.ndarray) -> dict | None:
    """A solved path's static stability (:func:`manifoldgen.stability.path_stability`) for a balance task, else None."""
    from manifoldgen.stability import balance_part, path_stability

    constraint = _scene(experiment.task, experiment.robot, experiment.scene)[0].constraint
    return path_stability(constraint, path).to_dict() if balance_part(constraint) is not None else None


def _physics(experiment: Experiment, path: np.ndarray) -> dict:
    """The verdict of executing a solved balance path in MuJoCo (:func:`manifoldgen.physics.check_path`)."""
    from manifoldgen.physics import balance_feet, check_path

    task = _scene(experiment.task, experiment.robot, experiment.scene)[0]
    result = check_path(task.robot, path, balance_feet(task.constraint.spec()))
    return {key: getattr(result, key) for key in ("upright", "stable", "fell", "max_tilt_deg", "max_slip_m",
                                                  "base_drift_m", "cpu_s")}


def _draw_snapshots(experiment: Experiment, records: list[dict], out_dir: Path) -> None:
    """``LABEL-snapshots.png``: robot snapshots along each method's run-0 path."""
    from manifoldgen.viz.snapshots import draw_snapshots

    task, scene = _scene(experiment.task, experiment.robot, experiment.scene)
    for record in records:
        draw_snapshots(np.asarray(record["path"]), task, scene, out_dir / f"{record['method']}-snapshots.png")


def _init_worker(parent: int) -> None:
    """One torch thread per worker process (the workers already share the cores); on Linux the worker
    is killed with its parent (``PR_SET_PDEATHSIG``), so a kill -9 of the benchmark leaves no orphans."""
    import sys
    if sys.platform.startswith("linux"):
        import ctypes
        import signal
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG = 1
        if os.getppid() != parent:  # the parent died before the line above
            os._exit(1)
    from manifoldgen.runtime import set_threads
    set_threads()


def worker_pool(workers: int) -> ProcessPoolExecutor:
    """The benchmark's pool: ``workers`` spawned processes that die with this one."""
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_init_worker, initargs=(os.getpid(),))


def read_records(path: Path) -> list[dict]:
    """Records of a ``runs.jsonl``; a truncated last line (an interrupted write) is ignored."""
    if not path.is_file():
        return []
    records, seen = [], set()
    lines = path.read_text().splitlines()
    for i, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
        except ValueError as exc:
            if i == len(lines) - 1:
                break
            raise ManifoldgenError(f"{path} line {i + 1} is not JSON ({exc}); remove that line or rerun into "
                                   "another folder") from None
        problem = record_problem(record)
        key = (record.get("method"), record.get("run")) if isinstance(record, dict) else None
        if not problem and key in seen:
            problem = f"a second record of run {key[1]} of '{key[0]}'"
        if problem:
            raise ManifoldgenError(f"{path} line {i + 1} is not a run record as bench writes it ({problem}); remove "
                                   "that line or rerun into another folder")
        seen.add(key)
        records.append(record)
    return records


# what every run record holds (run_once): its type, and for numbers the least value
_RECORD_FIELDS = {"method": str, "spec": str, "run": int, "seed": int, "scene": str, "time_limit": float,
                  "solved": bool, "planner_solved": bool, "valid": bool, "time_s": float, "length": float,
                  "iterations": int, "samples_drawn": int, "projections": int, "waypoints": int}


_RECORD_EXTRAS = ("build_s", "harness_cpu_s", "cpu_s", "ops", "late", "planner", "worst_violation", "reason", "why",
                  "extras", "stability", "physics", "path", "error",
                  "host", "node")  # what run_once writes besides _RECORD_FIELDS; a cluster run adds where it ran


def record_problem(record) -> str:
    """What is wrong with a run record read back from a ``runs.jsonl`` ('' when nothing): a missing field, a wrong
    type, a negative or non-finite number, a solved run without its path."""
    if not isinstance(record, dict):
        return "not an object"
    unknown = next((key for key in record if key not in _RECORD_FIELDS and key not in _RECORD_EXTRAS), None)
    if unknown is not None:
        return f"an unknown key {short(unknown)}"
    for key, kind in _RECORD_FIELDS.items():
        value = record.get(key)
        if kind is float:
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value) and value >= 0
        elif kind is int:
            ok = isinstance(value, int) and not isinstance(value, bool) and (value >= 0 or key == "seed")
        else:
            ok = isinstance(value, kind)
        if not ok:
            return f"{key} is {value!r}"
    cpu = record.get("cpu_s", 0.0)
    if not (isinstance(cpu, (int, float)) and not isinstance(cpu, bool) and np.isfinite(cpu) and cpu >= 0):
        return f"cpu_s is {cpu!r}"
    if record["solved"] and not isinstance(record.get("path"), list):
        return "a solved run without its path"
    return ""


def recheck_records(experiment: Experiment, records: list[dict], runs_path: Path) -> None:
    """Refuse a kept record that its run could not have written: a seed, scene or time limit not the experiment's,
    ``solved`` not what its planner's answer, validity and lateness give, a path whose waypoints or length are not
    the record's, or one the dense check of its method's space (the check a fresh run gives its path) judges
    otherwise than the record's ``valid`` says. (Times and counts are the run's own word.)"""
    from manifoldgen.planning.result import path_length

    spaces = {}
    for record in records:
        made = {"seed": experiment.seed + record["run"], "scene": experiment.scene,
                "time_limit": experiment.time_limit,
                "solved": record["planner_solved"] and record["valid"] and not record.get("late", False)}
        wrong = next((key for key, value in made.items() if record[key] != value), None)
        if wrong is not None:
            raise ManifoldgenError(f"{runs_path}: run {record['run']} of '{record['method']}' has {wrong} "
                                   f"{short(record[wrong])} where its run gives {short(made[wrong])}: the record was "
                                   "edited; remove that line to rerun it, or use another folder")
        if "path" not in record:
            continue
        sampler = Method.parse(record["spec"]).sampler
        kind = sampler if sampler in (BLIND, FEET_ONLY) else None
        space = spaces[kind] if kind in spaces else spaces.setdefault(kind, method_space(experiment, sampler))
        try:
            report = space.validate_path(np.asarray(record["path"], dtype=float))
        except (TypeError, ValueError):
            raise ManifoldgenError(f"{runs_path}: run {record['run']} of '{record['method']}' has a path that is not "
                                   "a list of configurations; remove that line or rerun into another folder") from None
        if report.valid != record["valid"]:
            found = "valid" if report.valid else f"invalid ({report.reason})"
            raise ManifoldgenError(f"{runs_path}: run {record['run']} of '{record['method']}' is recorded "
                                   f"{'valid' if record['valid'] else 'invalid'}, but its path rechecks {found}: "
                                   "the record was edited; remove that line to rerun it, or use another folder")
        path = np.asarray(record["path"], dtype=float)
        if record["waypoints"] != len(path) or not math.isclose(record["length"], path_length(path), rel_tol=1e-9,
                                                                  abs_tol=1e-9):
            raise ManifoldgenError(f"{runs_path}: run {record['run']} of '{record['method']}' records "
                                   f"{record['waypoints']} waypoints of length {record['length']:.6g}, but its path "
                                   f"has {len(path)} of length {path_length(path):.6g}: the record was edited; remove "
                                   "that line to rerun it, or use another folder")


def drop_truncated_line(path: Path) -> None:
    """Cut an unfinished last line (a run interrupted while being written) before appending."""
    if path.is_file():
        text = path.read_text()
        if text and not text.endswith("\n"):
            atomic_write_text(path, text[:text.rfind("\n") + 1])


def _append(path: Path, record: dict) -> None:
    with path.open("a") as f:
        f.write(json.dumps(record) + "\n")
        f.flush()
        os.fsync(f.fileno())


def _prepare_pg(experiment: Experiment, methods: list[Method], out_dir: Path, rows: int) -> list[Method]:
    """Give ``@pg`` methods a dataset: ``rows`` configurations at the scene's condition (collected once)."""
    if not any(m.sampler == "pg" for m in methods):
        return methods
    from manifoldgen.data import collect
    from manifoldgen.scene import get_scene
    from manifoldgen.tasks import get_task

    task = get_task(experiment.task, experiment.robot)
    y = get_scene(task, experiment.scene).condition
    path = out_dir / f"pg-{Path(experiment.scene).stem}-{rows}.npz"
    if not path.is_file():
        collect(task, rows, experiment.seed, path, conditions=y[None], progress=False)
    return [m.resolved(f"pg:{path}") if m.sampler == "pg" else m for m in methods]


def _folder_config(out_dir: Path, experiment: dict, methods: list[Method], resume: bool,
                   records: list[dict]) -> dict:
    """The folder's ``config.json`` after this run: the experiment, and the methods of its earlier runs with this
    run's added (a resume may add methods and runs). A folder with runs is refused without ``resume``; a resume
    with another experiment, or another spec under a label the folder holds, is refused naming the difference, and
    so is a config.json that does not list a method of the ``records`` (``runs.jsonl``) as they were made."""
    path = out_dir / CONFIG_FILE
    if records and not resume:
        raise ManifoldgenError(f"{out_dir} already holds {len(records)} runs; pass --resume to continue them or "
                               "choose another output folder")
    held: dict[str, str] = {}
    if path.is_file():  # read before it is replaced: a config.json bench did not write is not replaced
        try:
            old = json.loads(path.read_text())
            old_experiment, old_specs = dict(old["experiment"]), [str(spec) for spec in old["methods"]]
        except (ValueError, KeyError, TypeError):
            raise ManifoldgenError(f"{path} is not a config bench wrote (damaged, or someone else's); move or delete "
                                   f"it (the runs in {RUNS_FILE} are kept) or use another folder") from None
    if resume and path.is_file():
        changed = [f"{key} {old_experiment.get(key)!r}, not {value!r}" for key, value in experiment.items()
                   if old_experiment.get(key) != value]
        if changed:
            raise ManifoldgenError(f"{out_dir} was run with other settings: {'; '.join(changed[:3])}"
                                   f"{f' (and {len(changed) - 3} more)' if len(changed) > 3 else ''}; resume with "
                                   "the same scene, time limit, seed, task and settings, or choose another folder")
        held = {method.label: method.spec for method in map(Method.parse, old_specs)}
        unlisted = next((r for r in records if held.get(r["method"]) != r.get("spec")), None)
        if unlisted is not None:
            raise ManifoldgenError(f"{path} does not list method '{unlisted['method']}' as '{unlisted.get('spec')}', "
                                   f"which {RUNS_FILE} holds runs of: the folder was edited; restore config.json or "
                                   "use another folder")
        clash = next((m for m in methods if held.get(m.label, m.spec) != m.spec), None)
        if clash is not None:
            raise ManifoldgenError(f"{out_dir} holds method '{clash.label}' as '{held[clash.label]}', not "
                                   f"'{clash.spec}'; give that method another label or use another folder")
    return {"experiment": experiment, "methods": list({**held, **{m.label: m.spec for m in methods}}.values())}


def _run_local(experiment: Experiment, todo: list[tuple[Method, int]], workers: int, runs_path: Path, done: int):
    """Records of the ``todo`` runs from ``workers`` processes here, in the order they finish."""
    with worker_pool(workers) as pool:
        pending = {pool.submit(run_once, experiment, m, r) for m, r in todo}
        try:
            while pending:
                finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                for future in finished:
                    yield future.result()
                    done += 1
        except BaseException as exc:  # an interrupt or a crashed run: finished runs are already on disk
            for future in pending:
                future.cancel()
            if isinstance(exc, BrokenProcessPool):
                raise ManifoldgenError(f"a benchmark worker process died (killed, or out of memory); the "
                                       f"{done} finished runs are in {runs_path}: rerun with --resume "
                                       "(fewer --workers if memory ran out)") from None
            raise


def _inputs(experiment: Experiment, methods: list[Method]) -> list[str]:
    """The files every node must read: the scene and task files, and the methods' models and datasets."""
    from manifoldgen.specs import parse_spec

    named = [experiment.scene, experiment.task] + [parse_spec(m.sampler)[1] for m in methods
                                                   if m.sampler not in (None, BLIND, FEET_ONLY)]
    return [p for p in named if p and Path(p).exists()]


def _run_on_cluster(experiment: Experiment, methods: list[Method], todo: list[tuple[Method, int]],
                    cluster: Cluster):
    """Records of the ``todo`` runs, each a task on ``cluster``, with the ``host`` and ``node`` it ran on."""
    with connect(cluster) as pool:
        shared = pool.put(experiment)
        for _, record, node in pool.map_unordered(run_once, [(shared, m, r) for m, r in todo],
                                                  inputs=_inputs(experiment, methods)):
            yield {**record, **node}


@locks_output("out_dir")  # one benchmark per output folder
def run_bench(experiment: Experiment, methods: list[str], out_dir: str | Path, *, runs: int, workers: int = 1,
              resume: bool = False, pg_rows: int = 10_000, baseline: str | None = None,
              progress: bool = True, snapshots: bool = False, cluster: Cluster | None = None
              ) -> tuple[str, list[MethodSummary]]:
    """Run ``runs`` runs of every method (skipping finished ones with ``resume``; in ``workers`` processes here,
    or as tasks on ``cluster``); write
    ``runs.jsonl`` (every run's record with its path), ``config.json``, ``problem.json`` (:func:`problem_meta`),
    ``results.md``, ``time.png``, ``length.png`` in ``out_dir``;
    return the Markdown table and the summaries."""
    if runs <= 0 or workers <= 0:
        raise ManifoldgenError(f"--runs and --workers must be positive, got {runs} and {workers}")
    check_seed(experiment.seed + runs - 1, "--seed (+ --runs - 1: run r uses seed + r)")
    if cluster is None and workers > 2 * (os.cpu_count() or 1):  # each a local process with torch: more fill memory
        raise ManifoldgenError(f"--workers must be from 1 to {2 * (os.cpu_count() or 1)} (twice this machine's CPU "
                               f"count), got {workers}")
    if not 0 < pg_rows <= MAX_ROWS:
        raise ManifoldgenError(f"--pg-rows must be from 1 to {MAX_ROWS:,} dataset rows, got {pg_rows}")
    check_seed(experiment.seed)
    from manifoldgen.planning.base import check_time_limit
    check_time_limit(experiment.time_limit, "--time")
    parsed = [Method.parse(m) for m in methods]
    if not parsed:
        raise ManifoldgenError("no methods given; pass --methods (see `manifoldgen bench wall --help`)")
    labels = [m.label for m in parsed]
    duplicates = sorted({label for label in labels if labels.count(label) > 1})
    if duplicates:
        raise ManifoldgenError(f"methods share the labels {duplicates}; name them with LABEL=... ")
    if baseline is not None and baseline not in labels:
        raise ManifoldgenError(f"--baseline '{baseline}' is not one of the method labels {labels}")
    out_dir = Path(out_dir)
    check_own_folder(out_dir, BENCH_MARKERS)
    linked = next((out_dir / name for name in (RUNS_FILE, CONFIG_FILE) if (out_dir / name).is_symlink()), None)
    if linked is not None:
        raise ManifoldgenError(f"{linked} is a symbolic link; bench writes its own {linked.name} in the folder, never "
                               "through a link: remove the link or use another folder")
    for method in parsed:  # fail fast, before anything is written, on a bad model path, dataset or planner option
        build(experiment, method.resolved("uniform") if method.sampler == "pg" else method, experiment.seed)
    out_dir.mkdir(parents=True, exist_ok=True)
    runs_path = out_dir / RUNS_FILE
    records = read_records(runs_path)
    config = _folder_config(out_dir, experiment.to_dict(), parsed, resume, records)
    for record in records:
        match = next((m for m in parsed if m.label == record["method"]), None)
        if match is not None and match.spec != record.get("spec"):
            raise ManifoldgenError(f"{runs_path} has runs of '{match.label}' made with '{record['spec']}', not "
                                   f"'{match.spec}'; give that method another label or use another folder")
    recheck_records(experiment, records, runs_path)
    atomic_write_text(out_dir / CONFIG_FILE, json.dumps(config, indent=1))
    atomic_write_text(out_dir / PROBLEM_FILE, json.dumps(problem_meta(experiment), indent=1))
    drop_truncated_line(runs_path)
    parsed = _prepare_pg(experiment, parsed, out_dir, pg_rows)
    done = {(r["method"], r["run"]) for r in records}
    todo = [(m, r) for r in range(runs) for m in parsed if (m.label, r) not in done]
    with progress_bar(f"{experiment.scene}: runs", total=len(todo), enabled=progress) as bar:
        for record in (_run_local(experiment, todo, workers, runs_path, len(records)) if cluster is None else
                       _run_on_cluster(experiment, parsed, todo, cluster)):
            _append(runs_path, record)
            records.append(record)
            bar.advance(1)
    kept = [r for r in records if r["method"] in labels and r["run"] < runs]
    if snapshots:
        _draw_snapshots(experiment, [r for r in kept if r["run"] == 0 and "path" in r], out_dir)
    where = f"{workers} worker process(es)" if cluster is None else f"on {cluster.describe()}"
    others = sorted({r["method"] for r in records} - set(labels))
    notes = (f"Scene `{experiment.scene}` ({experiment.task} task, {experiment.robot}), {runs} runs per method "
             f"(seeds {experiment.seed}..{experiment.seed + runs - 1}), {where}. Methods:\n\n"
             + "\n".join(f"- `{m.label}`: `{m.spec}`" for m in parsed)
             + (f"\n\n{RUNS_FILE} also holds runs of {', '.join(f'`{o}`' for o in others)}, not in this table "
                "(resume with their --methods too to include them)." if others else ""))
    return write_report(kept, out_dir, f"{experiment.scene} benchmark", methods=labels, baseline=baseline,
                        notes=notes)
