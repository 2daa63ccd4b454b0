"""Queries by pose: a scene's start or goal given as an end-effector target instead of joint values.

A target is ``{"position": [x, y, z], "quaternion": [x, y, z, w], "frame": name}`` (quaternion optional:
position only; frame optional: the task constraint's own frame). It is turned into configurations
on the task's manifold at the scene's condition that reach the target (within the pose tolerances,
0.01 m and 0.01 rad), by projecting uniform seeds onto the task constraint and the target together,
then onto the task constraint alone, keeping the collision-free ones; when both ends are
targets, the pair of solutions closest in joint space is chosen (one IK branch, no flip on the way).
Given a configuration ``near`` (the task's home), half the seeds are drawn around it and the pair
chosen also stays close to it: both ends on the home's branch (for the dual-arm tray: the continuous
roll joints, cut at +-pi, away from the cut).
"""

from __future__ import annotations

import numpy as np

from manifoldgen.collision import CollisionChecker
from manifoldgen.constraints import Constraint, ConstraintSet, PoseConstraint
from manifoldgen.errors import ManifoldgenError
from manifoldgen.native import fast_space
from manifoldgen.space import ConstrainedSpace

SEEDS = 512  # seeds projected per target
NEAR_SPREAD = 0.3  # rad: standard deviation of the seeds drawn around ``near``
TARGET_KEYS = ("position", "quaternion", "frame")


def parse_target(data, what: str) -> dict:
    """Validate a target dict (see the module doc)."""
    unknown = [k for k in data if k not in TARGET_KEYS]
    if unknown or "position" not in data:
        raise ManifoldgenError(f"{what} target needs 'position' [x, y, z] and optionally 'quaternion' [x, y, z, w] "
                               f"and 'frame'; got keys {sorted(data)}")
    position = np.asarray(data["position"], float)
    if position.shape != (3,) or not np.all(np.isfinite(position)):
        raise ManifoldgenError(f"{what} target position must be 3 finite numbers, got {data['position']!r}")
    out = {"position": position.tolist()}
    if "quaternion" in data:
        quat = np.asarray(data["quaternion"], float)
        if quat.shape != (4,) or abs(np.linalg.norm(quat) - 1) > 1e-3:
            raise ManifoldgenError(f"{what} target quaternion must be a unit [x, y, z, w], got {data['quaternion']!r}")
        out["quaternion"] = (quat / np.linalg.norm(quat)).tolist()
    if "frame" in data:
        out["frame"] = str(data["frame"])
    return out


def constrained_frame(constraint: Constraint) -> str | None:
    """The frame a task constraint holds (its own, or its first part's), if any."""
    if isinstance(constraint, ConstraintSet):
        return next((f for f in map(constrained_frame, constraint.parts) if f), None)
    return getattr(constraint, "frame", None)


def solve_target(constraint: Constraint, y: np.ndarray, target: dict, checker: CollisionChecker | None,
                 what: str, seed: int = 0, near: np.ndarray | None = None) -> np.ndarray:
    """(S, n) distinct collision-free configurations on ``constraint`` at ``y`` that reach ``target``
    (half the seeds around ``near (n,)`` when given)."""
    robot = constraint.robot
    frame = target.get("frame") or constrained_frame(constraint)
    if frame is None:
        raise ManifoldgenError(f"{what} target names no 'frame' and the task's constraint holds none; add \"frame\"")
    rotation = np.eye(3)
    if "quaternion" in target:
        x, y_, z, w = target["quaternion"]
        rotation = _quaternion_matrix(x, y_, z, w)
    reach = PoseConstraint(robot, frame, rotation, [target["position"]], position_axes=("x", "y", "z"),
                           orientation_axes=("x", "y", "z") if "quaternion" in target else ())
    both = ConstraintSet([constraint, reach])
    yy = np.concatenate([np.asarray(y, float).reshape(-1), target["position"]])
    rng = np.random.default_rng(seed)
    seeds = robot.sample_uniform(SEEDS, rng)
    if near is not None:
        half = SEEDS // 2
        seeds[:half] = np.clip(near + rng.normal(0.0, NEAR_SPREAD, (half, robot.n)), robot.lower, robot.upper)
    # the compiled core's projection and validity where it takes the task (the same algorithm, faster)
    on_target = fast_space(ConstrainedSpace(both, yy, checker))
    reached = on_target.project(seeds, max_iters=100).q
    # tight on the task's manifold; the target need not lie exactly on it
    on = fast_space(ConstrainedSpace(constraint, np.asarray(y, float), checker)).project(reached)
    if not on.converged.any():
        names = ", ".join(f"{n} = {v:g}" for n, v in zip(constraint.condition.names, np.ravel(y)))
        raise ManifoldgenError(f"no configuration of {robot.name} satisfies the task at condition {names} "
                               f"({SEEDS} projected seeds); choose a condition inside "
                               f"{constraint.condition.describe()}")
    q = on.q[on.converged]
    valid = q[on_target.valid(q)]
    if not len(valid):
        at = f"at condition {np.round(y, 4).tolist()} puts {frame} at the {what} target {target['position']}"
        reaching = reach.satisfied(q, np.broadcast_to(target["position"], (len(q), 3)))
        if reaching.any():  # the target lies on the manifold; obstacles (or the robot itself) are in the way
            raise ManifoldgenError(f"no collision-free configuration on the task's manifold {at}: all "
                                   f"{int(reaching.sum())} that reach it collide ({SEEDS} projected seeds); move the "
                                   "target away from obstacles")
        miss = float(np.min(np.linalg.norm(robot.frame_pose(q, frame)[0] - np.asarray(target["position"]), axis=1)))
        raise ManifoldgenError(f"no collision-free configuration on the task's manifold {at}: the nearest of "
                               f"{len(q)} misses it by {miss:.3f} m; move the target within reach, onto the task's "
                               "manifold")
    return _distinct(valid)


def resolve_query(constraint: Constraint, y: np.ndarray, start, goal, checker: CollisionChecker | None,
                  near: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Start and goal as configurations (n,): joint vectors are kept; targets solved, on consistent branches
    (and close to ``near (n,)`` when given)."""
    ends = {"start": start, "goal": goal}
    options = {k: (solve_target(constraint, y, v, checker, k, near=near) if isinstance(v, dict)
                   else np.asarray(v)[None]) for k, v in ends.items()}
    d = np.linalg.norm(options["start"][:, None] - options["goal"][None], axis=2)
    if near is not None:
        d += (np.linalg.norm(options["start"] - near, axis=1)[:, None]
              + np.linalg.norm(options["goal"] - near, axis=1)[None])
    i, j = np.unravel_index(np.argmin(d), d.shape)
    return options["start"][i], options["goal"][j]


def _distinct(q: np.ndarray, tol: float = 1e-3) -> np.ndarray:
    """Rows of ``q (S, n)`` with duplicates (equal on a ``tol`` grid) dropped, in their first order."""
    first = np.unique(np.round(q / tol), axis=0, return_index=True)[1]
    return q[np.sort(first)]


def _quaternion_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
