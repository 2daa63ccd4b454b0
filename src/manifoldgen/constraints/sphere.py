"""A frame's position on a sphere: ``|p(q) - c| = r`` for a centre c and the radius r as the condition.

Residual (B, 1): ``|p(q) - c| - y`` (metres); analytic Jacobian ``u^T J_p`` with the unit vector
``u = (p - c) / |p - c|``. On a point robot of three prismatic joints this is OMPL's sphere demo.
"""

from __future__ import annotations

import numpy as np

from manifoldgen.constraints.base import CONSTRAINTS, Condition, Constraint, array_namespace, as_like
from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot


@CONSTRAINTS.register("sphere")
class SphereConstraint(Constraint):
    """``|p_frame(q) - center| = y``: the frame's origin at distance y (m) from ``center (3,)``."""

    def __init__(self, robot: Robot, frame: str, values, center=(0.0, 0.0, 0.0), tolerance: float = 0.01):
        robot.frame_id(frame)
        c = np.asarray(center, dtype=float)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise ManifoldgenError(f"sphere center must be 3 finite numbers [x, y, z], got {center!r}")
        radii = np.asarray(values, dtype=float).reshape(-1, 1)
        if not len(radii) or not np.all(radii > 0):
            raise ManifoldgenError(f"sphere values are radii (m) and must be positive, got {values!r}")
        if not tolerance > 0:
            raise ManifoldgenError(f"sphere tolerance must be a positive distance (m), got {tolerance!r}")
        self.robot, self.frame, self.center = robot, frame, c
        self.condition = Condition((f"{frame}.radius",), ("m",), radii)
        self.tolerance = np.array([float(tolerance)])

    def core_terms(self, y):
        return [{"type": "sphere", "frame": self.frame, "frame_id": self.robot.frame_id(self.frame),
                 "center": self.center.tolist(), "radius": float(y[0])}]

    def residual(self, q, y):
        q, y = self.batch(q, y)
        xp = array_namespace(q)
        p, _ = self.robot.frame_pose(q, self.frame)
        d = p - as_like(self.center, p)
        return xp.sqrt(xp.sum(d * d, axis=1, keepdims=True)) - y

    def jacobian(self, q, y):
        q, y = self.batch(q, y)
        p, _, J = self.robot.frame_jacobian(q, self.frame)
        d = p - self.center
        r = np.linalg.norm(d, axis=1, keepdims=True)
        u = d / np.maximum(r, 1e-12)
        return r - y, (u[:, None, :] @ J[:, :3])
