"""Sampling-based planners on constraint manifolds; ``PLANNERS`` is their registry (names in the
package, ``manifoldgen.planners`` entry points of other packages, ``module:Class``).

Every planner takes ``(space, sampler, *, local, seed, settings)`` (a
:class:`~manifoldgen.space.ConstrainedSpace`, a :class:`~manifoldgen.sampling.Sampler` at the
same condition) and answers ``solve(start, goal, time_limit) -> PlanResult``.
"""

from manifoldgen.planning.base import Planner, PlannerSettings
from manifoldgen.planning.cbirrt import CBiRRT, CBiRRTSettings
from manifoldgen.planning.kpiece import KPIECE, KPIECESettings
from manifoldgen.planning.local import DEFAULT_LOCAL, LOCAL_PLANNERS, make_local
from manifoldgen.planning.prm import PRM, PRMSettings
from manifoldgen.planning.result import PlanResult, path_length
from manifoldgen.planning.rrt import RRT, RRTSettings
from manifoldgen.planning.rrt_connect import RRTConnect, RRTConnectSettings
from manifoldgen.planning.sbl import SBL, SBLSettings
from manifoldgen.planning.smoothing import shortcut
from manifoldgen.registry import Registry

PLANNERS: Registry[Planner] = Registry("planner", Planner)
for _cls in (RRTConnect, RRT, PRM, KPIECE, CBiRRT, SBL):
    PLANNERS.register(_cls.name)(_cls)

__all__ = ["CBiRRT", "CBiRRTSettings", "DEFAULT_LOCAL", "KPIECE", "KPIECESettings", "LOCAL_PLANNERS", "PLANNERS",
           "PRM", "PRMSettings", "PlanResult", "Planner", "PlannerSettings", "RRT", "RRTConnect",
           "RRTConnectSettings", "RRTSettings", "SBL", "SBLSettings", "make_local", "path_length", "shortcut"]
