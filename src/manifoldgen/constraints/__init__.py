"""Constraints F(q, y) = 0, G(q, y) <= 0 and the projection onto them."""

from manifoldgen.constraints.balance import BalanceConstraint
from manifoldgen.constraints.base import Condition, Constraint, ConstraintSet
from manifoldgen.constraints.closed_chain import ClosedChainConstraint
from manifoldgen.constraints.pose import PoseConstraint
from manifoldgen.constraints.projection import Projection, project

__all__ = ["BalanceConstraint", "ClosedChainConstraint", "Condition", "Constraint", "ConstraintSet",
           "PoseConstraint", "Projection", "project"]
