"""Closed kinematic chain: a fixed relative pose between two end effectors (paper Section V-B).

Residual (B, 6): ``R_a^T (p_b - p_a) - d * axis`` (frame b seen from frame a, at distance
``d = y`` along ``axis`` of frame a), then ``log3(R_rel^T R_a^T R_b)``. Holding a tray
with two hands: ``d`` is the wrist distance the paper conditions on.
"""

from __future__ import annotations

import numpy as np

from manifoldgen.constraints.base import Condition, Constraint
from manifoldgen.constraints.so3 import hat, jlog3, log3
from manifoldgen.robot import Robot


class ClosedChainConstraint(Constraint):
    """Keep ``frame_b`` at distance y along ``axis`` of ``frame_a``, with relative rotation ``rotation``."""

    def __init__(self, robot: Robot, frame_a: str, frame_b: str, rotation: np.ndarray, values: np.ndarray,
                 axis: tuple[float, float, float] = (0.0, 1.0, 0.0), position_tolerance: float = 0.01,
                 orientation_tolerance: float = 0.01):
        robot.frame_id(frame_a), robot.frame_id(frame_b)
        self.robot, self.frame_a, self.frame_b = robot, frame_a, frame_b
        self.rotation = np.asarray(rotation, float)
        self.axis = np.asarray(axis, float) / np.linalg.norm(axis)
        self.condition = Condition(("distance",), ("m",), np.asarray(values, float))
        self.tolerance = np.array([position_tolerance] * 3 + [orientation_tolerance] * 3)

    def jacobian(self, q, y):
        q, y = self.batch(q, y)
        pa, Ra, Ja = self.robot.frame_jacobian(q, self.frame_a)
        pb, Rb, Jb = self.robot.frame_jacobian(q, self.frame_b)
        RaT = np.transpose(Ra, (0, 2, 1))
        r = pb - pa
        rel = np.einsum("bij,bj->bi", RaT, r) - y * self.axis
        err = log3(self.rotation.T @ RaT @ Rb)
        J_pos = RaT @ (Jb[:, :3] - Ja[:, :3] + hat(r) @ Ja[:, 3:])
        J_rot = jlog3(err) @ np.transpose(Rb, (0, 2, 1)) @ (Jb[:, 3:] - Ja[:, 3:])
        return np.concatenate([rel, err], axis=1), np.concatenate([J_pos, J_rot], axis=1)

    def residual(self, q, y):
        return self.jacobian(q, y)[0]

    def spec(self) -> dict:
        return {"type": "closed_chain", "frames": [self.frame_a, self.frame_b], "rotation": self.rotation.tolist(),
                "axis": self.axis.tolist(), "conditioned": "distance along axis of the first frame",
                "tolerance": {"position": float(self.tolerance[0]), "orientation": float(self.tolerance[-1])}}
