"""A frame's position on planes: one normal gives a plane, two a line, three a point.

Residual (B, r): ``N p(q) - y`` for the unit ``normals`` N (r, 3); the offsets y are the
condition (e.g. the height of a table plane, or a line's two coordinates).
"""

from __future__ import annotations

import numpy as np

from manifoldgen.constraints.base import CONSTRAINTS, Condition, Constraint, as_like
from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot


@CONSTRAINTS.register("plane")
class PlaneConstraint(Constraint):
    """``normals (r, 3) @ p_frame(q) = y (r,)``: the frame's origin on r planes at offsets y."""

    def __init__(self, robot: Robot, frame: str, normals, values, tolerance: float = 0.01):
        robot.frame_id(frame)
        N = np.atleast_2d(np.asarray(normals, dtype=float))
        if N.ndim != 2 or N.shape[1] != 3 or not 1 <= len(N) <= 3 or np.linalg.matrix_rank(N) < len(N):
            raise ManifoldgenError(f"plane normals must be 1 to 3 independent 3-vectors, got {normals!r}")
        self.robot, self.frame = robot, frame
        self.normals = N / np.linalg.norm(N, axis=1, keepdims=True)
        self.condition = Condition(tuple(f"{frame}.offset{i}" for i in range(len(N))), ("m",) * len(N),
                                   np.asarray(values, float))
        self.tolerance = np.full(len(N), float(tolerance))

    def residual(self, q, y):
        q, y = self.batch(q, y)
        p, _ = self.robot.frame_pose(q, self.frame)
        return p @ as_like(self.normals.T, p) - y

    def jacobian(self, q, y):
        q, y = self.batch(q, y)
        p, _, J = self.robot.frame_jacobian(q, self.frame)
        return p @ self.normals.T - y, self.normals @ J[:, :3]
