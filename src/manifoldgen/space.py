"""The constrained space: THE validity rule for configurations, motions and paths.

A configuration ``q (n,)`` is valid at the condition ``y (k,)`` when, tested in this order,

1. it lies inside the joint limits;
2. every equality residual is within its tolerance: ``max_i |F_i(q, y)| / tol_i <= limit``, with
   ``limit = 1`` for a state and ``1 - margin`` for the intermediate states of a checked motion
   (so that the final dense validation, at a finer resolution, almost never finds a state
   between two checked ones outside the tolerance);
3. every inequality holds: ``G(q, y) <= 0``;
4. it is collision-free (checked last and only on the rows that passed 1-3: the dearest test;
   along a motion, in order, stopping at the first collision).

A motion is a straight segment checked at its states; a path is valid when every state every
``settings.resolution`` along its segments is. Every sampler, collector, local planner, planner,
the OMPL bridge and the benchmarks ask this object; its counters say what the checks cost
(projections onto the manifold go through :meth:`ConstrainedSpace.project` to be counted too).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from manifoldgen.collision import CollisionChecker
from manifoldgen.constraints import Constraint, Projection, project
from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import as_batch

REASONS = ("limits", "constraint", "inequality", "collision")  # the tests, in the order they run
CHUNK = 4096  # states validated per batch


# the dense check's spacing, rad: finer would only exhaust memory, coarser is not a dense check (the outside
# checkers, examples/check_path.py, accept the same range)
RESOLUTION_RANGE = (1e-5, 0.05)


@dataclass(frozen=True)
class ValidationSettings:
    """resolution: spacing (rad, joint-space Euclidean) of the dense path validation, the one
    definition of it; margin: intermediate states of a checked motion keep within
    ``(1 - margin)`` x tolerance."""

    resolution: float = 0.005
    margin: float = 0.05

    def __post_init__(self):
        low, high = RESOLUTION_RANGE
        if not low <= self.resolution <= high or not 0 <= self.margin < 1:
            raise ManifoldgenError(f"validation needs resolution in [{low:g}, {high:g}] rad and 0 <= margin < 1, got "
                                   f"resolution {self.resolution}, margin {self.margin}")


@dataclass
class PathReport:
    """valid; worst_violation: max |F_i| / tol_i over every checked state; reason: '' or why not;
    segment: the first failing segment (-1 when valid); states_checked; resolution: the spacing used."""

    valid: bool
    worst_violation: float
    reason: str
    segment: int = -1
    states_checked: int = 0
    resolution: float = ValidationSettings.resolution

    def to_dict(self) -> dict:
        return {"valid": self.valid, "worst_violation": float(self.worst_violation), "reason": self.reason,
                "segment": self.segment, "states_checked": self.states_checked, "resolution": self.resolution}


def malformed_path(path: np.ndarray, n: int) -> str | None:
    """Why ``path`` is no path of ``(K >= 1, n)`` finite waypoints (one line), or None."""
    if path.ndim != 2 or path.shape[1] != n or len(path) == 0:
        return f"path must have shape (K, {n}) with K >= 1, got {path.shape}"
    if not np.all(np.isfinite(path)):
        return "path contains NaN or infinite values"
    return None


def densify(path: np.ndarray, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """States every ``resolution`` along each segment of ``path (K, n)`` -> (M, n) states and
    (M,) the segment each state lies on (the last waypoint belongs to segment K - 2)."""
    path = np.asarray(path, dtype=float)
    if len(path) == 1:
        return path.copy(), np.zeros(1, dtype=int)
    steps = np.maximum(1, np.ceil(np.linalg.norm(np.diff(path, axis=0), axis=1) / resolution).astype(int))
    segment = np.repeat(np.arange(len(steps)), steps)
    t = np.concatenate([np.arange(k) / k for k in steps])
    states = path[segment] + t[:, None] * (path[segment + 1] - path[segment])
    return np.concatenate([states, path[-1:]]), np.append(segment, len(steps) - 1)


class ConstrainedSpace:
    """The configurations of ``constraint.robot`` valid at condition ``y (k,)`` among ``checker``'s
    obstacles (None: no collision test), by the rule of the module doc.

    Counters since construction: ``evaluations`` (configurations whose constraint residual was
    evaluated), ``jacobians`` (configurations whose residual and Jacobian were evaluated, by
    :meth:`project`), ``projection_steps`` (projection iterations, summed over rows),
    ``collision_checks`` (configurations checked for collision), ``stopped`` (motion checks that
    stopped short, by the reason of their first invalid state); ``stop`` is that reason for the
    latest motion check (None when it passed).
    """

    def __init__(self, constraint: Constraint, y: np.ndarray, checker: CollisionChecker | None = None,
                 settings: ValidationSettings = ValidationSettings()):
        self.constraint, self.robot, self.checker, self.settings = constraint, constraint.robot, checker, settings
        condition = constraint.condition
        y = np.asarray(y, dtype=float).reshape(-1)
        if len(y) != condition.k or not np.all(np.isfinite(y)):
            raise ManifoldgenError(f"condition needs {condition.k} finite value(s) ({', '.join(condition.names)}), "
                                   f"got {y.tolist()}")
        tolerance = np.asarray(constraint.tolerance, dtype=float)
        if tolerance.ndim != 1 or not np.all(np.isfinite(tolerance) & (tolerance > 0)):
            raise ManifoldgenError(f"constraint tolerances must be positive and finite, got {tolerance.tolist()}; "
                                   "give each residual component a tolerance > 0")
        self.y = y
        self._inequalities = constraint.inequality(self.robot.lower[None], self.y).shape[1] > 0
        self.evaluations = self.jacobians = self.projection_steps = self.collision_checks = 0
        self.stopped = dict.fromkeys(REASONS, 0)
        self.stop: str | None = None

    @property
    def n(self) -> int:
        return self.robot.n

    def counts(self) -> dict:
        """The counters as a JSON-ready dict."""
        return {"evaluations": self.evaluations, "jacobians": self.jacobians,
                "projection_steps": self.projection_steps, "collision_checks": self.collision_checks,
                "stopped": dict(self.stopped)}

    # ---------------------------------------------------------------- the rule
    def violation(self, q: np.ndarray) -> np.ndarray:
        """(B,) worst ratio |F_i| / tol_i of ``q (B, n)`` (<= 1: within tolerance)."""
        q = as_batch(q, self.n)
        self.evaluations += len(q)
        return self.constraint.violation(q, self.y)

    def project(self, q: np.ndarray, **options) -> Projection:
        """:func:`~manifoldgen.constraints.project` of ``q (B, n)`` onto this condition's manifold
        (``options``: its keywords), counted: a row that stopped after ``i`` iterations evaluated
        ``i + 1`` residuals with Jacobians."""
        result = project(self.constraint, q, self.y, **options)
        self.jacobians += int(result.iterations.sum()) + len(result.iterations)
        self.projection_steps += int(result.iterations.sum())
        return result

    def _failures(self, q: np.ndarray, limit, equality: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(B,) code of the first failed test before collision (0: none; i + 1: ``REASONS[i]``) and
        (B,) violation, for ``q (B, n)`` and equality ``limit`` (scalar or (B,))."""
        code = np.where(self.robot.within_limits(q), 0, 1).astype(np.int8)
        violation = self.violation(q) if equality else np.zeros(len(q))
        code[(code == 0) & (violation > limit)] = 2
        if self._inequalities:
            code[(code == 0) & np.any(self.constraint.inequality(q, self.y) > 0, axis=1)] = 3
        return code, violation

    def _free_prefix(self, states: np.ndarray) -> int:
        """Leading collision-free rows of ``states (B, n)`` (checked in order)."""
        if self.checker is None or not len(states):
            return len(states)
        first = self.checker.first_collision(states)
        self.collision_checks += min(first + 1, len(states))
        return first

    def valid(self, q: np.ndarray, *, equality: bool = True) -> np.ndarray:
        """(B,) bool for configurations ``q (B, n)`` (``equality=False`` skips test 2, for spaces
        such as OMPL's that keep states on the manifold themselves)."""
        q = as_batch(q, self.n)
        ok = self._failures(q, 1.0, equality)[0] == 0
        if self.checker is not None and ok.any():
            self.collision_checks += int(ok.sum())
            ok[ok] = ~self.checker.in_collision(q[ok])
        return ok

    def valid_prefix(self, states: np.ndarray, last_is_node: bool) -> int:
        """How many leading rows of ``states (B, n)``, a motion's states in order, are valid; the
        intermediate ones need the margin, the last one, when it is a node (a state in its own
        right), the plain tolerance."""
        limit = np.full(len(states), 1.0 - self.settings.margin)
        if last_is_node:
            limit[-1] = 1.0
        code = self._failures(states, limit)[0]
        count = int(np.argmax(code != 0)) if code.any() else len(states)
        free = self._free_prefix(states[:count])
        self._stopped(None if count == len(states) and free == count else
                      "collision" if free < count else REASONS[code[count] - 1])
        return free

    def first_valid_piece(self, pieces: list[np.ndarray]) -> int:
        """Index of the first of ``pieces`` (each (k_i, n): a motion's states after a valid state,
        ending at a state) whose every state is valid, or -1. The tests before collision run on
        all pieces at once, collisions piece by piece in order."""
        sizes = np.array([len(p) for p in pieces])
        last = np.cumsum(sizes) - 1
        first = last - sizes + 1
        limit = np.full(last[-1] + 1, 1.0 - self.settings.margin)
        limit[last] = 1.0
        code = self._failures(np.concatenate(pieces), limit)[0]
        for i, piece in enumerate(pieces):
            codes = code[first[i]:last[i] + 1]
            if codes.any():
                self._stopped(REASONS[codes[np.argmax(codes != 0)] - 1])
            elif self._free_prefix(piece) < len(piece):
                self._stopped("collision")
            else:
                self.stop = None
                return i
        return -1

    def _stopped(self, reason: str | None) -> None:
        self.stop = reason
        if reason is not None:
            self.stopped[reason] += 1

    # ---------------------------------------------------------------- reports
    def problem(self, q: np.ndarray) -> str | None:
        """Why the configuration ``q (n,)`` is invalid (the first failed test, with names and
        values), or None when it is valid."""
        robot = self.robot
        q = np.asarray(q, dtype=float).reshape(self.n)
        outside = np.flatnonzero((q < robot.lower - 1e-9) | (q > robot.upper + 1e-9))
        if len(outside):
            j = outside[0]
            return (f"outside the joint limits: {robot.joints[j]} = {q[j]:.4f} not in "
                    f"[{robot.lower[j]:.4f}, {robot.upper[j]:.4f}]")
        self.evaluations += 1
        F = np.abs(self.constraint.residual(q[None], self.y[None])[0])
        ratio = F / self.constraint.tolerance
        if len(ratio) and ratio.max() > 1.0:
            i = int(np.argmax(ratio))
            return (f"violates the constraint: residual component {i} is {F[i]:.3g}, {ratio[i]:.2f} times its "
                    f"tolerance {self.constraint.tolerance[i]:g}")
        G = self.constraint.inequality(q[None], self.y[None])[0]
        if len(G) and G.max() > 0:
            return f"violates inequality {int(np.argmax(G))} of the constraint by {G.max():.3g}"
        if self.checker is not None and self._free_prefix(q[None]) == 0:
            names = ", ".join(f"{a} with {b}" for a, b in self.checker.collisions(q)[:3]) or "a checked pair"
            return f"is in collision: {names}"
        return None

    def check_query_state(self, q: np.ndarray, what: str) -> np.ndarray:
        """A start or goal ``q (n,)`` as floats; a clear error if it is malformed or invalid."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.n,) or not np.all(np.isfinite(q)):
            raise ManifoldgenError(f"{what} must be {self.n} finite joint values, got shape {q.shape}")
        problem = self.problem(q)
        if problem:
            raise ManifoldgenError(f"{what} configuration {problem}; {self._fix(problem, what)}")
        return q

    def _fix(self, problem: str, what: str) -> str:
        """What to do about a start or goal that fails :meth:`problem`: a condition outside the task's values
        comes first (the start and goal were most likely made for another one)."""
        if problem.startswith("is in collision"):
            return f"choose a collision-free {what} or move the obstacle"
        condition = self.constraint.condition
        outside = condition.k and np.any((self.y < condition.low - 1e-9) | (self.y > condition.high + 1e-9))
        if problem.startswith("violates") and outside:
            return (f"the condition {self.y.tolist()} lies outside the task's values ({condition.describe()}): "
                    f"check the scene's condition, or choose a {what} that satisfies the constraint there")
        return f"choose a {what} that satisfies the constraint (project it onto the manifold)"

    def validate_path(self, path: np.ndarray) -> PathReport:
        """Check every state every ``settings.resolution`` along the segments of ``path (K, n)``,
        however the path was made."""
        resolution = self.settings.resolution
        path = np.asarray(path, dtype=float)
        why = malformed_path(path, self.n)
        if why:
            return PathReport(False, np.inf, why, resolution=resolution)
        states, segment = densify(path, resolution)
        worst = 0.0
        for lo in range(0, len(states), CHUNK):
            chunk = states[lo:lo + CHUNK]
            code, violation = self._failures(chunk, 1.0)
            worst = max(worst, float(violation.max()))
            first = self._free_prefix(chunk[:int(np.argmax(code != 0)) if code.any() else len(chunk)])
            if first < len(chunk):
                i = lo + first
                return PathReport(False, worst, f"segment {segment[i]}: {self.problem(states[i])}", int(segment[i]),
                                  i + 1, resolution)
        return PathReport(True, worst, "", -1, len(states), resolution)
