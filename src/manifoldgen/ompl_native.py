"""The C++ OMPL baseline: OMPL's constrained spaces with our constraint and validity checker compiled.

A benchmark extra (``benchmarks/ompl_native/``, built by its ``build.sh`` against Debian's
``libompl-dev`` and the ``pin`` wheel's pinocchio and coal); manifoldgen runs without it.
:class:`NativeOmplPlanner` has the :class:`~manifoldgen.planning.base.Planner` contract and is the
``bench`` method ``ompl-native-SPACE`` (``projected``, ``atlas`` or ``tangent``, with RRTConnect).

The problem goes to the C++ program as a JSON file (:func:`export_problem`): the task spec for
people, and what the program builds from: the robot model and the collision model written by
pinocchio's own serialization from the very objects this space checks with (robot geometries,
scene obstacles, the exact collision pairs: SRDF-pruned or the sampled matrix), the locked joints'
reference, the joint limits (a floating base's six coordinates within the task's ``base_bounds``: OMPL's
state-space bounds), the constraint terms of the compiled core (pose, rotation, closed chain, sphere,
orientation, joint_linear, balance, and a user's Python constraint compiled from its traced expression;
tolerances), start, goal, seed and OMPL settings. OMPL plans at native
speed: the equalities are OMPL's constraint, and they, their Jacobian and the validity test (joint limits,
then the inequalities (balance's CoM margin, orientation's hemisphere), then collision, as
:meth:`~manifoldgen.space.ConstrainedSpace.valid` with ``equality=False``, like the Python bridge) are C++ calls.

Tolerance: exactly as :class:`~manifoldgen.ompl_bridge.OmplConstraint`: OMPL gets ``F_i / tol_i``
and the tolerance ``1 - margin`` on its Euclidean norm, so a state OMPL accepts is within our
per-component tolerance with the margin our planners keep for intermediate states.

Final check and retry: every exact OMPL solution (densified by OMPL's ``interpolate``) comes back
over a pipe and is checked here by the space's rule, the same dense check (every
``ValidationSettings.resolution`` rad) every method gets, at the same speed as our planners get it: by the
compiled core's ``validate_path`` with certified constraints when the core is built (its counts booked on the
space), else by
:meth:`~manifoldgen.space.ConstrainedSpace.validate_path`. A rejected path does not end the query:
as our planners go on searching after a candidate fails the dense check, OMPL searches again
(``SimpleSetup::clear``: a new tree, the atlas keeps its charts) until a path passes or the time
limit is reached. ``time_s`` runs from the go signal to the answer (the program's start-up and
model loading excluded, as our planners' construction is); ``extras['native_cpu_s']`` is the
program's CPU over the same span, which the benchmark adds to this process's CPU.
"""

from __future__ import annotations

import json
import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from manifoldgen.errors import ManifoldgenError
from manifoldgen import native
from manifoldgen.core_extension import active_coordinates, core_module, unsupported, write_models
from manifoldgen.core_terms import constraint_terms
from manifoldgen.ompl_settings import OmplSettings
from manifoldgen.planning.base import check_time_limit
from manifoldgen.planning.result import PlanResult, path_length
from manifoldgen.space import REASONS, ConstrainedSpace

SPACES = ("projected", "atlas", "tangent")
BINARY_ENV = "MANIFOLDGEN_OMPL_NATIVE"
SOURCE_DIR = Path(__file__).resolve().parents[2] / "benchmarks" / "ompl_native"


def native_binary() -> Path:
    """The built C++ program (``$MANIFOLDGEN_OMPL_NATIVE`` or the source tree's build folder);
    a one-line error saying how to build it when it is missing."""
    path = Path(os.environ.get(BINARY_ENV) or SOURCE_DIR / "build" / "ompl_native")
    if not (path.is_file() and os.access(path, os.X_OK)):
        raise ManifoldgenError(f"the C++ OMPL baseline is not built ({path} missing): apt-get install libompl-dev, "
                               f"then run benchmarks/ompl_native/build.sh, or set {BINARY_ENV} to the program")
    return path


def _terms(space: ConstrainedSpace) -> list[dict]:
    """The space's constraint as the C++ terms (:func:`manifoldgen.core_terms.constraint_terms`, the compiled
    core's: built-in terms and compiled Python constraints); a Python constraint that does not compile is
    refused."""
    try:
        reason = unsupported(space)
        if reason:
            raise ManifoldgenError(reason)
        return constraint_terms(space)
    except ManifoldgenError as exc:
        raise ManifoldgenError(f"the C++ OMPL baseline cannot take this task ({exc}); use the Python-callback "
                               "ompl-SPACE-PLANNER methods") from None


def export_problem(space: ConstrainedSpace, start: np.ndarray, goal: np.ndarray, folder: Path, *,
                   ompl_space: str, resolution: float, seed: int, time_limit: float,
                   settings: OmplSettings, spheres: bool = False) -> Path:
    """Write ``problem.json``, ``model.bin`` and ``geometry.bin`` into ``folder``; the JSON's path. ``spheres``:
    the program's collision checks use the robot's sphere models first, as the core's do with them."""
    robot = space.robot
    terms = _terms(space)
    folder = Path(folder)
    model_file, geometry_file = write_models(space, folder)
    names = [robot.model.names[1]] if robot.floating_base else []  # the free flyer: the six base coordinates
    names += [robot.model.names[j] for j in robot._joint_ids]
    active = [{"joint": joint, "idx_q": idx_q, "idx_v": idx_v, "nq": nq}
              for joint, (idx_q, idx_v, nq) in zip(names, active_coordinates(robot))]
    problem = {
        "format_version": 1,
        "task": {"robot": robot.identity, "joints": robot.joints, "locked": robot.locked,
                 "constraint": space.constraint.spec(), "condition": space.y.tolist()},
        "model_file": str(model_file), "geometry_file": str(geometry_file),
        "reference": robot.reference.tolist(), "active": active,
        "lower": robot.lower.tolist(), "upper": robot.upper.tolist(),
        "constraint": {"terms": terms, "tolerance": space.constraint.tolerance.tolist()},
        "start": np.asarray(start, float).tolist(), "goal": np.asarray(goal, float).tolist(),
        "settings": {"space": ompl_space, "planner": "rrtconnect", "delta": resolution,
                     "lambda": settings.lambda_, "range": settings.range,
                     "tolerance": 1.0 - space.settings.margin, "max_iterations": settings.max_iterations,
                     "time_limit": time_limit, "seed": int(seed), "shortcut": settings.shortcut,
                     "epsilon": settings.epsilon, "rho": settings.rho, "alpha": settings.alpha,
                     "exploration": settings.exploration, "separated": settings.separated},
    }
    if spheres and space.checker is not None:  # the core's sphere broad phase (same verdicts, cheaper checks)
        model = native.space_spheres(space)
        problem["spheres"] = {"joint": np.asarray(model["joint"], int).tolist(),
                              "center": np.asarray(model["center"], float).tolist(),
                              "radius": np.asarray(model["radius"], float).tolist(),
                              "geometry": np.asarray(model["geometry"], int).tolist(),
                              "exact": [[int(a), int(b)] for a, b in model["exact"]]}
    path = folder / "problem.json"
    path.write_text(json.dumps(problem, indent=1))
    return path


def evaluate(space: ConstrainedSpace, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The C++ side's residual (B, m), Jacobian (B, m, n) and collision-free flags (B,) for ``q (B, n)``
    (to compare with the Python side's)."""
    q = np.atleast_2d(np.asarray(q, float))
    m, n = space.constraint.m, space.n
    with tempfile.TemporaryDirectory(prefix="ompl-native-") as folder:
        problem = export_problem(space, q[0], q[0], Path(folder), ompl_space="atlas", resolution=0.05, seed=0,
                                 time_limit=1.0, settings=OmplSettings())
        text = "\n".join(" ".join(repr(float(v)) for v in row) for row in q) + "\n"
        done = subprocess.run([str(native_binary()), "--evaluate", str(problem)], input=text, capture_output=True,
                              text=True, check=False)
    if done.returncode:
        raise ManifoldgenError(f"the C++ OMPL baseline failed: {done.stderr.strip().splitlines()[-1:]}")
    rows = np.array([[float(v) for v in line.split()] for line in done.stdout.splitlines()])
    return rows[:, :m], rows[:, m:m + m * n].reshape(-1, m, n), rows[:, -1].astype(bool)


class NativeOmplPlanner:
    """OMPL ``ompl_space`` + RRTConnect in C++ for our ``space`` (see the module docstring).

    resolution: OMPL's manifold step ``delta`` (rad); seed: OMPL's RNG seed (as the Python
    bridge sets it, so both draw the same numbers for a seed); settings: as the Python bridge's; spheres:
    the collision checks (the search's and the final dense check's) use the robot's sphere models as the broad
    phase, as our planner's do by default (``spheres=True``: same verdicts, cheaper checks).
    """

    def __init__(self, space: ConstrainedSpace, *, ompl_space: str = "atlas", resolution: float = 0.05,
                 seed: int = 0, settings: OmplSettings | None = None, spheres: bool = True):
        if ompl_space not in SPACES:
            raise ManifoldgenError(f"unknown native OMPL space '{ompl_space}'; known: {', '.join(SPACES)}")
        if resolution <= 0:
            raise ManifoldgenError(f"resolution must be positive, got {resolution}")
        _terms(space)  # refuse an unsupported constraint now, not at solve time
        self.binary = native_binary()
        self.settings = OmplSettings() if settings is None else settings
        self.settings.check()
        self.space, self.ompl_space, self.resolution, self.seed = space, ompl_space, resolution, seed
        self.core = native.core_space(space) if core_module() is not None else None  # the dense check
        self.spheres = spheres and space.checker is not None
        self.dense_sphere_checks = 0  # sphere tests of the current solve's dense checks (spheres only)
        self.dense_sweep_checks = 0  # certified sweep tests of those dense checks (spheres only)
        self.dense_cpu_s = 0.0  # CPU of the current solve's dense checks (this process)
        if self.spheres and self.core is not None:
            native.set_spheres(self.core, native.space_spheres(space))
        self.name = f"ompl-native-{ompl_space}"

    def solve(self, start: np.ndarray, goal: np.ndarray, time_limit: float) -> PlanResult:
        """Plan from ``start (n,)`` to ``goal (n,)`` within ``time_limit`` seconds."""
        check_time_limit(time_limit)
        n = self.space.n
        start, goal = (self.space.check_query_state(q, what) for q, what in ((start, "start"), (goal, "goal")))
        self.dense_sphere_checks = self.dense_sweep_checks = 0
        self.dense_cpu_s = 0.0
        with tempfile.TemporaryDirectory(prefix="ompl-native-") as folder:
            problem = export_problem(self.space, start, goal, Path(folder), ompl_space=self.ompl_space,
                                     resolution=self.resolution, seed=self.seed, time_limit=time_limit,
                                     settings=self.settings, spheres=self.spheres)
            log = Path(folder) / "stderr.txt"  # a file, not a pipe: OMPL's warnings can never block the program
            with log.open("w") as errors, subprocess.Popen([str(self.binary), str(problem)], stdin=subprocess.PIPE,
                                                           stdout=subprocess.PIPE, stderr=errors, text=True) as child:
                try:
                    self._expect(child, log, "ready")
                    began = time.perf_counter()
                    path, worst, reason, done = self._converse(child, log, time_limit, n)
                    elapsed = time.perf_counter() - began
                finally:
                    if child.poll() is None:
                        child.kill()
        solved = bool(done["solved"])
        extras = {"space": self.ompl_space, "ompl_planner": "rrtconnect", "ompl_status": done["status"],
                  "ompl_solved": solved or done["rejected_paths"] > 0, "vertices": done["vertices"],
                  "charts": done["charts"], "attempts": done["attempts"], "rejected_paths": done["rejected_paths"],
                  "resolution": self.resolution, "ompl_tolerance": 1.0 - self.space.settings.margin,
                  "native_ops": {k: done[k] for k in ("fk", "jacobians", "inequalities", "collision_checks",
                                                      "samples")},
                  "sphere_checks": done["sphere_checks"] + self.dense_sphere_checks,
                  "sweep_checks": self.dense_sweep_checks,
                  "native_cpu_s": done["cpu_s"], "native_wall_s": done["wall_s"], "load_s": done["load_s"],
                  "dense_cpu_s": self.dense_cpu_s,
                  **({"found_length": done["found_length"], "shortened": done["shortened"]}
                     if solved and self.settings.shortcut else {}),
                  "valid": solved, "worst_violation": worst, "reason": reason}
        path = path if solved else np.zeros((0, n))
        return PlanResult(solved, path, elapsed, int(done["vertices"]), 0, int(done["projections"]), self.name,
                          path_length(path), extras)

    def _converse(self, child, log: Path, time_limit: float, n: int):
        """Send go, answer every candidate path with our dense check; (path, worst violation, reason of
        the last rejection, the program's closing report)."""
        child.stdin.write(f"go {time_limit!r}\n")
        child.stdin.flush()
        accepted, worst, reason = np.zeros((0, n)), float("nan"), ""
        while True:
            line = self._expect(child, log, "path", "done")
            if line.startswith("done "):
                return accepted, worst, reason, json.loads(line[5:])
            count = int(line.split()[1])
            path = np.array([[float(v) for v in child.stdout.readline().split()] for _ in range(count)])
            cpu = time.process_time()
            valid, checked_worst, why = self._dense_check(path)
            self.dense_cpu_s += time.process_time() - cpu
            if valid:  # the latest valid path is the answer (a shortened one that fails keeps the one before)
                accepted, worst, reason = path, checked_worst, ""
            elif not len(accepted):
                worst, reason = checked_worst, why
            child.stdin.write("valid\n" if valid else "invalid\n")
            child.stdin.flush()

    def _dense_check(self, path: np.ndarray) -> tuple[bool, float, str]:
        """The space's dense check of ``path (K, n)``: (valid, worst violation, reason); in the core with certified
        constraints, as our planner's (the same verdict; worst over the states it evaluated)."""
        if self.core is None:
            report = self.space.validate_path(path)
            return report.valid, report.worst_violation, report.reason
        before = self.core.counts()
        valid, worst, _, reason, segment, _ = self.core.validate_path(np.ascontiguousarray(path, float), certify=True)
        after = self.core.counts()
        native.book(self.space, before, after)
        self.dense_sphere_checks += after["sphere_checks"] - before["sphere_checks"]
        self.dense_sweep_checks += after["sweep_checks"] - before["sweep_checks"]
        return bool(valid), float(worst), "" if valid else f"segment {segment}: {REASONS[reason - 1]}"

    @staticmethod
    def _expect(child, log: Path, *words: str) -> str:
        line = child.stdout.readline()
        if not line.startswith(words):
            child.kill()
            child.wait()
            message = log.read_text().strip().splitlines()
            raise ManifoldgenError(f"the C++ OMPL baseline failed: {message[-1] if message else 'no answer'}; "
                                   "rebuild it with benchmarks/ompl_native/build.sh")
        return line.strip()
