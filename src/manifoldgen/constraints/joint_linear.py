"""Linear constraints in joint space: ``A q = y`` (coupled joints, a fixed sum, a joint held at y).

``coefficients`` is (r, n) over the planning group's joints, in the group's order.
"""

from __future__ import annotations

import numpy as np

from manifoldgen.constraints.base import CONSTRAINTS, Condition, Constraint, as_like
from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot

MIN_ROW_NORM = 1e-9  # a coefficient row shorter than this cannot move its residual


@CONSTRAINTS.register("joint_linear")
class JointLinearConstraint(Constraint):
    """``coefficients (r, n) @ q = y (r,)`` within ``tolerance`` (rad or m) per row."""

    def __init__(self, robot: Robot, coefficients, values, tolerance: float = 0.01):
        A = np.atleast_2d(np.asarray(coefficients, dtype=float))
        if A.ndim != 2 or A.shape[1] != robot.n or not np.all(np.isfinite(A)) \
                or np.any(np.linalg.norm(A, axis=1) < MIN_ROW_NORM):
            raise ManifoldgenError(f"joint_linear coefficients must be rows of {robot.n} numbers (one per joint "
                                   f"of {', '.join(robot.joints)}), none all zero (a norm under {MIN_ROW_NORM:g}); "
                                   f"got shape {A.shape}")
        self.robot, self.coefficients = robot, A
        self.condition = Condition(tuple(f"joint_linear{i}" for i in range(len(A))), ("",) * len(A),
                                   np.asarray(values, float))
        self.tolerance = np.full(len(A), float(tolerance))
        span = np.abs(A) @ (robot.upper - robot.lower)  # (r,) the range of each row's A q over the joint limits
        flat = np.flatnonzero(span <= 2 * self.tolerance)
        if len(flat):
            i = int(flat[0])
            raise ManifoldgenError(f"joint_linear row {i} constrains nothing: over the joint limits its A q spans "
                                   f"only {span[i]:.3g}, within twice the tolerance {float(tolerance):g}; scale the "
                                   "row's coefficients up or lower the tolerance")

    def core_terms(self, y):
        return [{"type": "linear", "A": self.coefficients.tolist(), "y": np.asarray(y, float).tolist()}]

    def residual(self, q, y):
        q, y = self.batch(q, y)
        return q @ as_like(self.coefficients.T, q) - y

    def jacobian(self, q, y):
        q, y = self.batch(q, y)
        return q @ self.coefficients.T - y, np.broadcast_to(self.coefficients, (len(q), *self.coefficients.shape))
