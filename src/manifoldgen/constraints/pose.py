"""End-effector pose constraint (paper Section V-A): fixed world orientation, conditioned position.

Residual (B, a + 3): ``p_axes(q) - y`` for the conditioned position axes, then
``log3(R_target^T R(q))``. Defaults: 0.01 m and 0.01 rad per component.
"""

from __future__ import annotations

import numpy as np

from manifoldgen.constraints.base import Condition, Constraint
from manifoldgen.constraints.so3 import jlog3, log3
from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot

AXES = {"x": 0, "y": 1, "z": 2}


class PoseConstraint(Constraint):
    """Keep ``frame`` at world ``rotation`` (3, 3) with its position along ``position_axes`` = y."""

    def __init__(self, robot: Robot, frame: str, rotation: np.ndarray, values: np.ndarray,
                 position_axes: tuple[str, ...] = ("z",), position_tolerance: float = 0.01,
                 orientation_tolerance: float = 0.01):
        robot.frame_id(frame)
        rotation = np.asarray(rotation, dtype=float)
        if rotation.shape != (3, 3) or not np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-6):
            raise ManifoldgenError("pose constraint rotation must be a 3x3 rotation matrix")
        unknown = [a for a in position_axes if a not in AXES]
        if unknown:
            raise ManifoldgenError(f"unknown position axes {unknown}; use x, y and/or z")
        self.robot, self.frame, self.rotation = robot, frame, rotation
        self.position_axes = tuple(position_axes)
        self._idx = [AXES[a] for a in position_axes]
        self.condition = Condition(tuple(f"{frame}.{a}" for a in position_axes),
                                   ("m",) * len(position_axes), np.asarray(values, float))
        self.tolerance = np.array([position_tolerance] * len(position_axes) + [orientation_tolerance] * 3)

    def _error(self, p, R, y):
        return np.concatenate([p[:, self._idx] - y, log3(self.rotation.T @ R)], axis=1)

    def residual(self, q, y):
        q, y = self.batch(q, y)
        p, R = self.robot.frame_pose(q, self.frame)
        return self._error(p, R, y)

    def jacobian(self, q, y):
        q, y = self.batch(q, y)
        p, R, J = self.robot.frame_jacobian(q, self.frame)
        F = self._error(p, R, y)
        J_rot = jlog3(F[:, -3:]) @ np.transpose(R, (0, 2, 1)) @ J[:, 3:]
        return F, np.concatenate([J[:, self._idx], J_rot], axis=1)

    def spec(self) -> dict:
        return {"type": "pose", "frame": self.frame, "rotation": self.rotation.tolist(),
                "position_axes": list(self.position_axes),
                "tolerance": {"position": float(self.tolerance[0]),
                              "orientation": float(self.tolerance[-1])}}
