"""End-effector pose constraint (paper Section V-A): fixed world orientation, conditioned position.

Residual (B, a + o): ``p_axes(q) - y`` for the conditioned position axes, then the chosen
components of ``log3(R_target^T R(q))`` (all three by default). Defaults: 0.01 m and
0.01 rad per component.
"""

from __future__ import annotations

import numpy as np

from manifoldgen.constraints.base import CONSTRAINTS, Condition, Constraint, array_namespace, as_like
from manifoldgen.constraints.so3 import jlog3, log3
from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot

AXES = {"x": 0, "y": 1, "z": 2}


def axis_indices(axes, what: str) -> list[int]:
    """``["x", "z"]`` -> ``[0, 2]``, refusing unknown or repeated names."""
    axes = list(axes)
    unknown = [a for a in axes if a not in AXES]
    if unknown or len(set(axes)) != len(axes):
        raise ManifoldgenError(f"{what} {axes} must be distinct names among x, y, z")
    return [AXES[a] for a in axes]


def rotation_matrix(rotation, what: str = "rotation") -> np.ndarray:
    """A (3, 3) rotation matrix, refusing anything else."""
    R = np.asarray(rotation, dtype=float)
    if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ManifoldgenError(f"{what} must be a 3x3 rotation matrix (orthonormal, det +1), got {rotation!r}")
    return R


@CONSTRAINTS.register("pose")
class PoseConstraint(Constraint):
    """Keep ``frame`` at world ``rotation`` (3, 3) (about ``orientation_axes``) with its position
    along ``position_axes`` = y; ``values`` (V, a) are the training conditions."""

    def __init__(self, robot: Robot, frame: str, rotation, values, position_axes=("z",),
                 orientation_axes=("x", "y", "z"), position_tolerance: float = 0.01,
                 orientation_tolerance: float = 0.01):
        robot.frame_id(frame)
        self.robot, self.frame, self.rotation = robot, frame, rotation_matrix(rotation, "pose rotation")
        self._idx = axis_indices(position_axes, "pose position_axes")
        self._oidx = axis_indices(orientation_axes, "pose orientation_axes")
        if not len(self._idx):
            raise ManifoldgenError("pose needs at least one of position_axes (its condition, e.g. [\"z\"]); for an "
                                   "orientation alone use the orientation constraint")
        self.condition = Condition(tuple(f"{frame}.{a}" for a in position_axes), ("m",) * len(self._idx),
                                   np.asarray(values, float))
        self.tolerance = np.array([position_tolerance] * len(self._idx) + [orientation_tolerance] * len(self._oidx))

    def core_terms(self, y):
        return [{"type": "pose", "frame": self.frame, "frame_id": self.robot.frame_id(self.frame),
                 "rotation": self.rotation.reshape(-1).tolist(), "position_axes": list(self._idx),
                 "orientation_axes": list(self._oidx), "y": np.asarray(y, float).tolist()}]

    def residual(self, q, y):
        q, y = self.batch(q, y)
        p, R = self.robot.frame_pose(q, self.frame)
        err = log3(as_like(self.rotation.T, p) @ R)
        return array_namespace(p).concat([p[:, self._idx] - y, err[:, self._oidx]], axis=1)

    def jacobian(self, q, y):
        q, y = self.batch(q, y)
        p, R, J = self.robot.frame_jacobian(q, self.frame)
        err = log3(self.rotation.T @ R)
        J_rot = jlog3(err) @ np.transpose(R, (0, 2, 1)) @ J[:, 3:]
        F = np.concatenate([p[:, self._idx] - y, err[:, self._oidx]], axis=1)
        return F, np.concatenate([J[:, self._idx], J_rot[:, self._oidx]], axis=1)
