"""Constraints F(q, y) = 0, G(q, y) <= 0, their registry and the projection onto them.

``array_namespace`` is re-exported for user constraints (numpy or torch operations alike).
"""


from manifoldgen.constraints.balance import BalanceConstraint
from manifoldgen.constraints.base import (CONSTRAINTS, Condition, Constraint, ConstraintSet, array_namespace, as_like,
                                          build_constraint, own_jacobian)
from manifoldgen.constraints.closed_chain import ClosedChainConstraint
from manifoldgen.constraints.joint_linear import JointLinearConstraint
from manifoldgen.constraints.orientation import OrientationConstraint
from manifoldgen.constraints.plane import PlaneConstraint
from manifoldgen.constraints.pose import PoseConstraint
from manifoldgen.constraints.projection import Projection, project
from manifoldgen.constraints.rotation import RotationConstraint
from manifoldgen.constraints.sphere import SphereConstraint

__all__ = ["CONSTRAINTS", "BalanceConstraint", "ClosedChainConstraint", "Condition", "Constraint", "ConstraintSet",
           "JointLinearConstraint", "OrientationConstraint", "PlaneConstraint", "PoseConstraint", "Projection",
           "RotationConstraint", "SphereConstraint", "array_namespace", "as_like", "build_constraint", "own_jacobian",
           "project"]
