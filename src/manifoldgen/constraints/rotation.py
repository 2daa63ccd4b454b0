"""World rotation turned by a conditioned angle: "keep the tray level, at wrist pitch y".

Residual (B, 3): ``log3(R_target(y)^T R(q))`` with ``R_target(y) = Rot(axis, y) @ rotation``: the
frame's fixed world ``rotation`` (3, 3), turned by the conditioned angle ``y`` (rad) about the world
``axis`` (the paper's wrist pitch for the dual-arm tray). Default tolerance 0.01 rad per component.
"""

from __future__ import annotations

import numpy as np

from manifoldgen.constraints.base import CONSTRAINTS, Condition, Constraint, array_namespace, as_like
from manifoldgen.constraints.orientation import unit
from manifoldgen.constraints.pose import rotation_matrix
from manifoldgen.constraints.so3 import hat, jlog3, log3
from manifoldgen.robot import Robot


@CONSTRAINTS.register("rotation")
class RotationConstraint(Constraint):
    """``frame``'s world rotation is ``Rot(axis, y) @ rotation``; ``values`` (V, 1) are the training angles."""

    def __init__(self, robot: Robot, frame: str, rotation, values, axis=(0.0, 1.0, 0.0), name: str = "pitch",
                 tolerance: float = 0.01):
        robot.frame_id(frame)
        self.robot, self.frame = robot, frame
        self.rotation = rotation_matrix(rotation, "rotation constraint's rotation")
        self.axis = unit(axis, "rotation constraint's axis")
        self.condition = Condition((str(name),), ("rad",), np.asarray(values, float))
        self.tolerance = np.full(3, float(tolerance))

    def target(self, y):
        """(B, 3, 3) target rotations for angles ``y (B, 1)`` (numpy or torch)."""
        xp = array_namespace(y)
        K = as_like(hat(self.axis[None])[0], y)
        s, c = xp.sin(y)[:, :, None], xp.cos(y)[:, :, None]
        turn = as_like(np.eye(3), y) + s * K + (1 - c) * (K @ K)
        return turn @ as_like(self.rotation, y)

    def core_terms(self, y):
        """A pose term without position axes, its target turned by ``y``."""
        return [{"type": "pose", "frame": self.frame, "frame_id": self.robot.frame_id(self.frame),
                 "rotation": self.target(np.asarray(y, float)[None])[0].reshape(-1).tolist(), "position_axes": [],
                 "orientation_axes": [0, 1, 2], "y": []}]

    def residual(self, q, y):
        q, y = self.batch(q, y)
        _, R = self.robot.frame_pose(q, self.frame)
        return log3(self.target(y).mT @ R)

    def jacobian(self, q, y):
        q, y = self.batch(q, y)
        _, R, J = self.robot.frame_jacobian(q, self.frame)
        err = log3(np.transpose(self.target(y), (0, 2, 1)) @ R)
        return err, jlog3(err) @ np.transpose(R, (0, 2, 1)) @ J[:, 3:]
