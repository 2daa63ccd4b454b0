"""Closed kinematic chain: a fixed relative pose between two end effectors (paper Section V-B).

Residual (B, 6): ``R_a^T (p_b - p_a) - d * axis`` (frame b seen from frame a, at distance
``d = y`` along ``axis`` of frame a), then ``log3(R_rel^T R_a^T R_b)``. Holding a tray
with two hands: ``d`` is the wrist distance the paper conditions on.
"""

from __future__ import annotations

import numpy as np

from manifoldgen.constraints.base import CONSTRAINTS, Condition, Constraint, array_namespace, as_like
from manifoldgen.constraints.orientation import unit
from manifoldgen.constraints.pose import rotation_matrix
from manifoldgen.constraints.so3 import hat, jlog3, log3
from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot


@CONSTRAINTS.register("closed_chain")
class ClosedChainConstraint(Constraint):
    """Keep ``frame_b`` at distance y along ``axis`` of ``frame_a``, with relative rotation ``rotation``."""

    def __init__(self, robot: Robot, frame_a: str, frame_b: str, rotation, values,
                 axis=(0.0, 1.0, 0.0), position_tolerance: float = 0.01, orientation_tolerance: float = 0.01):
        robot.frame_id(frame_a), robot.frame_id(frame_b)
        if frame_a == frame_b:
            raise ManifoldgenError(f"closed chain frames are both '{frame_a}'; give two different frames")
        ja, jb = (robot.model.frames[robot.frame_id(f)].parentJoint for f in (frame_a, frame_b))
        if ja == jb or ja in robot._ancestors(jb) or jb in robot._ancestors(ja):
            raise ManifoldgenError(f"closed chain frames '{frame_a}' and '{frame_b}' are on one kinematic chain (one "
                                   "arm): nothing closes; give a frame on each arm (e.g. the two grippers)")
        self.robot, self.frame_a, self.frame_b = robot, frame_a, frame_b
        self.rotation = rotation_matrix(rotation, "closed chain rotation")
        self.axis = unit(axis, "closed chain axis")
        self.condition = Condition(("distance",), ("m",), np.asarray(values, float))
        self.tolerance = np.array([position_tolerance] * 3 + [orientation_tolerance] * 3)

    def core_terms(self, y):
        """A ``chain`` term: the frames' ids, the rotation between them and the offset ``d * axis``."""
        return [{"type": "chain", "frame_a": self.frame_a, "frame_b": self.frame_b,
                 "frame_a_id": self.robot.frame_id(self.frame_a), "frame_b_id": self.robot.frame_id(self.frame_b),
                 "rotation": self.rotation.reshape(-1).tolist(), "offset": (float(y[0]) * self.axis).tolist()}]

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
        q, y = self.batch(q, y)
        pa, Ra = self.robot.frame_pose(q, self.frame_a)
        pb, Rb = self.robot.frame_pose(q, self.frame_b)
        RaT = Ra.mT
        rel = (RaT @ (pb - pa)[:, :, None])[:, :, 0] - y * as_like(self.axis, pa)
        err = log3(as_like(self.rotation.T, Ra) @ RaT @ Rb)
        return array_namespace(pa).concat([rel, err], axis=1)
