"""OMPL's knobs, shared by the Python-callback bridge (:mod:`manifoldgen.ompl_bridge`, which needs the [ompl]
extra) and the C++ baseline (:mod:`manifoldgen.ompl_native`, which does not)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

from manifoldgen.errors import ManifoldgenError

PREFIX = "ompl_"  # benchmark settings for OMPL's side only (``--set ompl_epsilon=0.1``); unprefixed ones are ours


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
    (the C++ baseline; 0: the path as found), the budget our planners' ``shortcut`` setting gets. The atlas's own
    knobs (the C++ baseline's atlas and tangent spaces; OMPL's defaults): epsilon, a chart's largest distance from
    the manifold; rho, its radius (0: OMPL's 5 x the step delta); alpha, its largest angle to the manifold (rad);
    exploration, the share of samples drawn on the atlas's frontier; separated, charts bounded by their
    neighbours' half-spaces.
    """

    max_iterations: int = 50
    lambda_: float = 2.0
    range: float = 0.6
    sample_attempts: int = 10
    shortcut: int = 0
    epsilon: float = 0.05
    rho: float = 0.0
    alpha: float = math.pi / 8
    exploration: float = 0.75
    separated: bool = True

    def check(self) -> None:
        if (self.max_iterations < 1 or self.lambda_ <= 1 or self.range < 0 or self.sample_attempts < 1
                or self.shortcut < 0 or not self.epsilon > 0 or self.rho < 0 or not 0 < self.alpha < math.pi / 2
                or not 0 <= self.exploration < 1):
            raise ManifoldgenError(f"invalid OMPL settings {asdict(self)}: need max_iterations >= 1, lambda_ > 1, "
                                   "range >= 0, sample_attempts >= 1, shortcut >= 0, epsilon > 0, rho >= 0, "
                                   "0 < alpha < pi/2, 0 <= exploration < 1")

    @classmethod
    def from_benchmark(cls, values: dict) -> OmplSettings:
        """The settings a benchmark gives OMPL: its ``ompl_KEY`` values (``ompl_lambda`` for ``lambda_``) and the
        ``shortcut`` budget both sides share; the rest of ``values`` are our planners'."""
        known = {PREFIX + f.name.rstrip("_"): f.name for f in fields(cls) if f.name != "shortcut"}
        return cls(shortcut=int(values.get("shortcut", 0)),
                   **{known[k]: v for k, v in values.items() if k in known})


def benchmark_keys() -> dict:
    """``ompl_KEY`` -> default for every OMPL setting a benchmark's ``--set`` may give (the ``shortcut`` budget is
    shared, unprefixed)."""
    return {PREFIX + f.name.rstrip("_"): f.default for f in fields(OmplSettings) if f.name != "shortcut"}
