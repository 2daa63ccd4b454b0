"""Static stability along a path, and the balance-blind baseline's space.

:func:`path_stability` checks a path ``(K, n)`` of a task with a balance constraint (alone or in a
constraint set) state by state, every ``resolution`` rad along its segments: how deep the centre of
mass's ground projection lies inside the support polygon (negative: outside, the robot tips over),
how far the feet have moved from their fixed spots. :func:`blind_space` is the space of a planner that
ignores balance: joint limits and collisions only (uniform samples, the feet free to leave the ground),
the baseline whose paths the paper says make the robot fall "most of the time"; :func:`feet_only_space`
keeps the feet on their spots (and the base height) but ignores the centre of mass.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from manifoldgen.collision import CollisionChecker
from manifoldgen.constraints import BalanceConstraint, Condition, Constraint, ConstraintSet
from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot
from manifoldgen.space import ConstrainedSpace, ValidationSettings, densify


def balance_part(constraint: Constraint) -> BalanceConstraint | None:
    """The balance constraint of ``constraint`` (itself or a part of a set), or None."""
    if isinstance(constraint, BalanceConstraint):
        return constraint
    if isinstance(constraint, ConstraintSet):
        return next((b for b in map(balance_part, constraint.parts) if b is not None), None)
    return None


@dataclass
class StabilityReport:
    """A path's static stability: ``states`` checked every ``resolution``; ``unstable``: states whose CoM
    projection is outside the support polygon, ``unstable_fraction`` their share; ``below_margin_fraction``:
    states closer than the constraint's margin to an edge (or outside); ``min_depth`` (m): the CoM's smallest
    depth inside the polygon (negative: outside); ``feet_moved_fraction``: states with a foot off its spot by
    more than the tolerance; ``max_foot_drift`` (m)."""

    states: int
    unstable: int
    unstable_fraction: float
    below_margin_fraction: float
    min_depth: float
    feet_moved_fraction: float
    max_foot_drift: float
    resolution: float

    @property
    def stable(self) -> bool:
        """Every state statically stable, the feet on their spots."""
        return self.unstable == 0 and self.feet_moved_fraction == 0

    def to_dict(self) -> dict:
        return asdict(self)


def path_stability(constraint: Constraint, path: np.ndarray,
                   resolution: float = ValidationSettings.resolution) -> StabilityReport:
    """Check ``path (K, n)`` against the balance part of ``constraint`` (see the module doc)."""
    balance = balance_part(constraint)
    if balance is None:
        raise ManifoldgenError("the task has no balance constraint: static stability needs feet and a support "
                               "polygon; use a balance task (e.g. `balance --robot centauro`)")
    path = np.asarray(path, float)
    if path.ndim != 2 or path.shape[1] != balance.robot.n or not len(path):
        raise ManifoldgenError(f"a path of shape (K, {balance.robot.n}) is needed, got {path.shape}")
    states = densify(path, resolution)[0]
    depth = balance.com_depth(states)
    feet = np.stack([balance.robot.frame_pose(states, f)[0] for f in balance.feet], axis=1)  # (M, F, 3)
    drift = np.linalg.norm(feet - balance.foot_positions, axis=2).max(axis=1)
    moved = np.any(np.abs(feet - balance.foot_positions) > balance.tolerance[0], axis=(1, 2))
    return StabilityReport(len(states), int((depth < 0).sum()), float((depth < 0).mean()),
                           float((depth < balance.margin).mean()), float(depth.min()), float(moved.mean()),
                           float(drift.max()), resolution)


class _NoConstraint(Constraint):
    """No equality, no inequality, no condition: only the joint limits (and collisions) remain."""

    def __init__(self, robot: Robot):
        self.robot = robot
        self.condition = Condition((), (), np.zeros((1, 0)))
        self.tolerance = np.zeros(0)

    def residual(self, q, y):
        q, _ = self.batch(q, y)
        return q[:, :0]


def blind_space(robot: Robot, checker: CollisionChecker | None,
                settings: ValidationSettings = ValidationSettings()) -> ConstrainedSpace:
    """The balance-blind planner's space: joint limits and ``checker``'s collisions, no task constraint."""
    return ConstrainedSpace(_NoConstraint(robot), np.zeros(0), checker, settings)


def feet_only_space(constraint: Constraint, y: np.ndarray, checker: CollisionChecker | None,
                    settings: ValidationSettings = ValidationSettings()) -> ConstrainedSpace:
    """The space of a planner blind to the centre of mass: ``constraint`` (a balance constraint, alone or in a set)
    with its CoM inequality switched off (the feet stay on their spots, the base at its height; a set's other parts,
    e.g. upright wheels, kept), limits, collisions."""
    balance = balance_part(constraint)
    if balance is None:
        raise ManifoldgenError("the feet-only baseline needs a task with a balance constraint")
    arguments = {k: v for k, v in balance.spec().items() if k != "type"}
    blind = BalanceConstraint(balance.robot, **{**arguments, "margin": -1e9})
    if isinstance(constraint, ConstraintSet):
        blind = ConstraintSet([blind if part is balance else part for part in constraint.parts])
    return ConstrainedSpace(blind, y, checker, settings)
