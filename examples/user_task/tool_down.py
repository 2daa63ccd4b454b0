"""A user's own constraint: the tool points straight down at a chosen world x (conditioned on x)."""

import numpy as np

from manifoldgen.constraints import Condition, Constraint, array_namespace


class ToolDownAtX(Constraint):
    """Residual (B, 3): the frame's x minus y, and the x, y components of its z axis (zero when it points down)."""

    def __init__(self, robot, frame, values, tolerance=0.01):
        robot.frame_id(frame)  # a clear error for an unknown frame
        self.robot, self.frame = robot, frame
        self.condition = Condition(("x",), ("m",), np.asarray(values, float))
        self.tolerance = np.full(3, tolerance)

    def residual(self, q, y):
        q, y = self.batch(q, y)
        p, R = self.robot.frame_pose(q, self.frame)  # numpy arrays or torch tensors, like q
        return array_namespace(q).concat([p[:, :1] - y, R[:, :2, 2]], axis=1)
