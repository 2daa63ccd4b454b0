"""A user's own constraint: a tool frame stays on a sphere of radius y around a fixed point (conditioned on y)."""

import numpy as np

from manifoldgen.constraints import Condition, Constraint, array_namespace, as_like


class ToolOnSphere(Constraint):
    """Residual (B, 1): the frame's distance from ``center`` minus the radius y; its orientation is free."""

    def __init__(self, robot, frame, center, values, tolerance=0.01):
        robot.frame_id(frame)  # a clear error for an unknown frame
        self.robot, self.frame = robot, frame
        self.center = np.asarray(center, float).reshape(3)
        self.condition = Condition(("radius",), ("m",), np.asarray(values, float))
        self.tolerance = np.full(1, tolerance)

    def residual(self, q, y):
        q, y = self.batch(q, y)
        p, _ = self.robot.frame_pose(q, self.frame)  # numpy arrays or torch tensors, like q
        xp = array_namespace(q)
        return xp.linalg.vector_norm(p - as_like(self.center, q), axis=1, keepdims=True) - y
