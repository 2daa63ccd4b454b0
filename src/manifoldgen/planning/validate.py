"""Independent path validation: every linear interpolant between waypoints, densely.

A path is valid when every state on the straight segments between consecutive waypoints,
taken every ``resolution`` rad (Euclidean in joint space), satisfies the constraint within
tolerance (and its inequalities), lies inside the joint limits and is collision-free.
Validation does not care how the path was made.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from manifoldgen.collision import CollisionChecker
from manifoldgen.constraints import Constraint
from manifoldgen.errors import ManifoldgenError

CHUNK = 4096  # states checked per batch


@dataclass
class PathReport:
    """valid; worst_violation: max |F_i| / tol_i over every checked state; reason: '' or why not;
    segment: the first failing segment (-1 when valid); states_checked."""

    valid: bool
    worst_violation: float
    reason: str
    segment: int = -1
    states_checked: int = 0

    def to_dict(self) -> dict:
        return {"valid": self.valid, "worst_violation": float(self.worst_violation), "reason": self.reason,
                "segment": self.segment, "states_checked": self.states_checked}


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


def validate_path(path: np.ndarray, constraint: Constraint, y: np.ndarray, checker: CollisionChecker | None,
                  resolution: float = 0.005) -> PathReport:
    """Check every linear interpolant of ``path (K, n)`` at ``resolution`` rad."""
    robot = constraint.robot
    path = np.asarray(path, dtype=float)
    if path.ndim != 2 or path.shape[1] != robot.n or len(path) == 0:
        return PathReport(False, np.inf, f"path must have shape (K, {robot.n}) with K >= 1, got {path.shape}")
    if not np.all(np.isfinite(path)):
        return PathReport(False, np.inf, "path contains NaN or infinite values")
    if resolution <= 0:
        raise ManifoldgenError(f"validation resolution must be positive, got {resolution}")
    states, segment = densify(path, resolution)
    worst = 0.0
    for lo in range(0, len(states), CHUNK):
        chunk = states[lo:lo + CHUNK]
        worst = max(worst, float(constraint.violation(chunk, y).max()))
        ok = constraint.satisfied(chunk, y)
        first = len(chunk) if ok.all() else int(np.argmin(ok))
        if checker is not None and first:
            first = checker.first_collision(chunk[:first])
        if first < len(chunk):
            i = lo + first
            problem = state_problem(states[i], constraint, y, checker)
            return PathReport(False, worst, f"segment {segment[i]}: {problem}", int(segment[i]), i + 1)
    return PathReport(True, worst, "", -1, len(states))


def state_problem(q: np.ndarray, constraint: Constraint, y: np.ndarray, checker: CollisionChecker | None) -> str | None:
    """Why one configuration ``q (n,)`` is invalid (limits, constraint, collision), or None."""
    robot = constraint.robot
    q = np.asarray(q, dtype=float).reshape(robot.n)
    outside = np.flatnonzero((q < robot.lower - 1e-9) | (q > robot.upper + 1e-9))
    if len(outside):
        j = outside[0]
        return (f"outside the joint limits: {robot.joints[j]} = {q[j]:.4f} not in "
                f"[{robot.lower[j]:.4f}, {robot.upper[j]:.4f}]")
    F = np.abs(constraint.residual(q, y)[0])
    ratio = F / constraint.tolerance
    if ratio.max() > 1.0:
        i = int(np.argmax(ratio))
        return (f"violates the constraint: residual component {i} is {F[i]:.3g}, {ratio[i]:.2f} times its "
                f"tolerance {constraint.tolerance[i]:g}")
    G = constraint.inequality(q, y)[0]
    if len(G) and G.max() > 0:
        return f"violates inequality {int(np.argmax(G))} of the constraint by {G.max():.3g}"
    if checker is not None and checker.in_collision(q)[0]:
        pairs = checker.collisions(q)
        names = ", ".join(f"{a} with {b}" for a, b in pairs[:3]) or "a checked pair"
        return f"is in collision: {names}"
    return None


def check_query_state(q: np.ndarray, what: str, constraint: Constraint, y: np.ndarray,
                      checker: CollisionChecker | None) -> np.ndarray:
    """A start or goal ``q (n,)`` as floats; a clear error if it is malformed, off the manifold or colliding."""
    n = constraint.robot.n
    q = np.asarray(q, dtype=float)
    if q.shape != (n,) or not np.all(np.isfinite(q)):
        raise ManifoldgenError(f"{what} must be {n} finite joint values, got shape {q.shape}")
    problem = state_problem(q, constraint, y, checker)
    if problem:
        fix = (f"choose a collision-free {what} or move the obstacle" if problem.startswith("is in collision")
               else f"choose a {what} that satisfies the constraint (project it onto the manifold)")
        raise ManifoldgenError(f"{what} configuration {problem}; {fix}")
    return q
