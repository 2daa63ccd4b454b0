"""Sampling-based planners on constraint manifolds; ``PLANNERS`` is their registry (names in the
package, ``manifoldgen.planners`` entry points of other packages, ``module:Class``).

Every planner takes ``(space, sampler, *, local, seed, settings)`` (a
:class:`~manifoldgen.space.ConstrainedSpace`, a :class:`~manifoldgen.sampling.Sampler` at the
same condition) and answers ``solve(start, goal, time_limit) -> PlanResult``; :func:`planner_settings` lists
a planner's settings. The planner modules are imported when first named, so listing the names imports neither
torch nor the compiled core.
"""

from __future__ import annotations

import importlib
from dataclasses import asdict
from typing import TYPE_CHECKING

from manifoldgen.registry import Registry

if TYPE_CHECKING:
    from manifoldgen.planning.base import Planner

PLANNERS: Registry[Planner] = Registry("planner", "manifoldgen.planning.base:Planner", {
    "rrtconnect": "manifoldgen.planning.rrt_connect:RRTConnect", "rrt": "manifoldgen.planning.rrt:RRT",
    "prm": "manifoldgen.planning.prm:PRM", "kpiece": "manifoldgen.planning.kpiece:KPIECE",
    "cbirrt": "manifoldgen.planning.cbirrt:CBiRRT", "sbl": "manifoldgen.planning.sbl:SBL"})
_HOMES = {"Planner": "base", "PlannerSettings": "base", "CBiRRT": "cbirrt", "CBiRRTSettings": "cbirrt",
          "KPIECE": "kpiece", "KPIECESettings": "kpiece", "DEFAULT_LOCAL": "local", "LOCAL_PLANNERS": "local",
          "make_local": "local", "PRM": "prm", "PRMSettings": "prm", "PlanResult": "result",
          "path_length": "result", "RRT": "rrt", "RRTSettings": "rrt", "RRTConnect": "rrt_connect",
          "RRTConnectSettings": "rrt_connect", "SBL": "sbl", "SBLSettings": "sbl", "shortcut": "smoothing",
          "relax": "smoothing"}


def __getattr__(name: str):
    if name in _HOMES:
        return getattr(importlib.import_module(f"manifoldgen.planning.{_HOMES[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def planner_settings(planner: str) -> dict:
    """The settings ``planner`` takes (field -> default), for ``--set`` checking."""
    return asdict(PLANNERS.get(planner).settings_type())


__all__ = ["PLANNERS", "planner_settings", *_HOMES]
