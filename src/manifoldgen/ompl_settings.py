"""OMPL's knobs, shared by the Python-callback bridge (:mod:`manifoldgen.ompl_bridge`, which needs the [ompl]
extra) and the C++ baseline (:mod:`manifoldgen.ompl_native`, which does not)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

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

    def check(self, prefix: str = "") -> None:
        """Refuse the first setting outside its range, named as given (``prefix``: a benchmark's ``ompl_``)."""
        for name, (rule, ok) in _RULES.items():
            value = getattr(self, name)
            if not ok(value):
                key = name if name == "shortcut" else prefix + name.rstrip("_")
                raise ManifoldgenError(f"invalid OMPL settings: {key} is {value!r}; need {rule.format(key)}")

    @classmethod
    def from_benchmark(cls, values: dict) -> OmplSettings:
        """The settings a benchmark gives OMPL: its ``ompl_KEY`` values (``ompl_lambda`` for ``lambda_``) and the
        ``shortcut`` budget both sides share; the rest of ``values`` are our planners'."""
        known = {PREFIX + f.name.rstrip("_"): f.name for f in fields(cls) if f.name != "shortcut"}
        settings = cls(shortcut=int(values.get("shortcut", 0)),
                       **{known[k]: v for k, v in values.items() if k in known})
        settings.check(PREFIX)
        return settings


_RULES = {"max_iterations": ("{} >= 1", lambda v: v >= 1), "lambda_": ("{} > 1", lambda v: v > 1),
          "range": ("{} >= 0", lambda v: v >= 0), "sample_attempts": ("{} >= 1", lambda v: v >= 1),
          "shortcut": ("{} >= 0", lambda v: v >= 0), "epsilon": ("{} > 0", lambda v: v > 0),
          "rho": ("{} >= 0", lambda v: v >= 0), "alpha": ("0 < {} < pi/2", lambda v: 0 < v < math.pi / 2),
          "exploration": ("0 <= {} < 1", lambda v: 0 <= v < 1)}  # each setting's range: NaN is outside every one


def benchmark_keys() -> dict:
    """``ompl_KEY`` -> default for every OMPL setting a benchmark's ``--set`` may give (the ``shortcut`` budget is
    shared, unprefixed)."""
    return {PREFIX + f.name.rstrip("_"): f.default for f in fields(OmplSettings) if f.name != "shortcut"}
