"""OMPL's knobs, shared by the Python-callback bridge (:mod:`manifoldgen.ompl_bridge`, which needs the [ompl]
extra) and the C++ baseline (:mod:`manifoldgen.ompl_native`, which does not)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

from manifoldgen.errors import ManifoldgenError


@dataclass
class OmplSettings:
    """OMPL knobs (OMPL's scalar tolerance is ``1 - margin`` of the space's validation settings
    on the tolerance-scaled residual, see :class:`~manifoldgen.ompl_bridge.OmplConstraint`: the margin our own planners
    keep for intermediate states).

    max_iterations: Newton iterations per projection (OMPL's default 50); lambda_: OMPL's
    limit on manifold-walk length / chord length; range: planner range in rad, by default
    our planners' (``PlannerSettings.range``; 0: OMPL's default, 20% of the space extent,
    2.6 rad for the panda, which makes tree planners slower in clutter); sample_attempts: draws from our sampler per OMPL
    request before giving up; shortcut: attempts of OMPL's ``PathSimplifier::shortcutPath`` on an accepted path
    (the C++ baseline; 0: the path as found), the budget our planners' ``shortcut`` setting gets.
    """

    max_iterations: int = 50
    lambda_: float = 2.0
    range: float = 0.6
    sample_attempts: int = 10
    shortcut: int = 0

    def check(self) -> None:
        if (self.max_iterations < 1 or self.lambda_ <= 1 or self.range < 0 or self.sample_attempts < 1
                or self.shortcut < 0):
            raise ManifoldgenError(f"invalid OMPL settings {asdict(self)}: need max_iterations >= 1, lambda_ > 1, "
                                   "range >= 0, sample_attempts >= 1, shortcut >= 0")
