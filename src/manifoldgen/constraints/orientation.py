"""Orientation with one free rotation: a frame's axis points along a world direction.

"Keep the cup upright": the frame's ``axis`` (in its own coordinates) stays along the world
``direction``; rotation about that direction is free. Residual (B, 2): the pointing vector
``R(q) axis`` along two unit vectors ``e1, e2`` perpendicular to ``direction`` (each the sine of
the tilt towards it, about the tilt in radians); full rank, so Atlas and tangent-bundle spaces take
it. Inequality (B, 1): ``-direction . R(q) axis <= 0`` keeps the axis in ``direction``'s hemisphere
(the residual alone is zero upside down too). Nothing is conditioned.
"""

from __future__ import annotations

import numpy as np

from manifoldgen.constraints.base import CONSTRAINTS, Condition, Constraint, as_like
from manifoldgen.constraints.so3 import hat
from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot


def unit(vector, what: str) -> np.ndarray:
    """A unit (3,) vector from a non-zero one."""
    v = np.asarray(vector, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)) or np.linalg.norm(v) < 1e-9:
        raise ManifoldgenError(f"{what} must be a non-zero 3-vector, got {vector!r}")
    return v / np.linalg.norm(v)


def perpendicular_basis(direction: np.ndarray) -> np.ndarray:
    """(2, 3) unit rows e1, e2 with (e1, e2, direction) right-handed; e1 = direction x (x or y axis), normalised."""
    helper = np.eye(3)[0] if abs(direction[0]) < 0.9 else np.eye(3)[1]
    e1 = np.cross(direction, helper)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(direction, e1)])


@CONSTRAINTS.register("orientation")
class OrientationConstraint(Constraint):
    """``frame``'s local ``axis`` (3,) points along world ``direction`` (3,), within ``tolerance`` per component."""

    def __init__(self, robot: Robot, frame: str, axis=(0.0, 0.0, 1.0), direction=(0.0, 0.0, 1.0),
                 tolerance: float = 0.01):
        robot.frame_id(frame)
        self.robot, self.frame = robot, frame
        self.axis, self.direction = unit(axis, "orientation axis"), unit(direction, "orientation direction")
        self.basis = perpendicular_basis(self.direction)
        self.condition = Condition((), (), np.zeros((1, 0)))
        self.tolerance = np.full(2, float(tolerance))

    def _pointing(self, q):
        _, R = self.robot.frame_pose(q, self.frame)
        return R @ as_like(self.axis, R)

    def core_terms(self, y):
        """Its two residual rows as an ``orientation`` term (axis, basis) and its ``hemisphere`` inequality."""
        frame_id = self.robot.frame_id(self.frame)
        return [{"type": "orientation", "frame": self.frame, "frame_id": frame_id, "axis": self.axis.tolist(),
                 "basis": self.basis.tolist()},
                {"type": "hemisphere", "frame": self.frame, "frame_id": frame_id, "axis": self.axis.tolist(),
                 "direction": self.direction.tolist()}]

    def residual(self, q, y):
        q, y = self.batch(q, y)
        return self._pointing(q) @ as_like(self.basis.T, q)

    def inequality(self, q, y):
        q, y = self.batch(q, y)
        return -(self._pointing(q) @ as_like(self.direction[:, None], q))

    def jacobian(self, q, y):
        q, y = self.batch(q, y)
        _, R, J = self.robot.frame_jacobian(q, self.frame)
        pointing = R @ self.axis
        return pointing @ self.basis.T, self.basis @ (-hat(pointing) @ J[:, 3:])
