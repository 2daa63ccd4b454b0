"""RRT (LaValle 1998): one tree from the start, grown toward samples and, now and then, the goal."""

from __future__ import annotations

import time
from dataclasses import dataclass

from manifoldgen.errors import ManifoldgenError
from manifoldgen.planning.base import Planner, PlannerSettings, Tree


@dataclass
class RRTSettings(PlannerSettings):
    """goal_bias: probability of growing toward the goal instead of a sample; goal_radius: how far
    from the goal (rad) a goal-biased target may lie (see :meth:`Planner._goal_target`)."""

    goal_bias: float = 0.05
    goal_radius: float = 1.8

    def check(self) -> None:
        super().check()
        if not 0 <= self.goal_bias <= 1 or self.goal_radius <= 0:
            raise ManifoldgenError(f"RRT needs goal_bias in [0, 1] and goal_radius > 0, got {self.goal_bias}, "
                                   f"{self.goal_radius}")


class RRT(Planner):
    """Single-tree RRT. With probability ``goal_bias`` it grows greedily toward a target near the
    goal (see :meth:`Planner._toward_goal`), else one step toward a sample; a new node within
    ``range`` of the goal, or closer to it than any before, tries to reach it."""

    name = "rrt"
    settings_type = RRTSettings

    def _solve(self, start, goal, deadline):
        tree = Tree(start)
        self.trees = [tree]
        self._start_pool(self.trees, deadline)
        while time.perf_counter() < deadline:
            self.iterations += 1
            if self.rng.random() < self.settings.goal_bias:
                path = self._toward_goal(goal, self.settings.goal_radius, deadline)
            else:
                new = self._grow(0, self._draw())
                path = None if new is None else self._reach_goal(tree, new, goal)
            if path is not None:
                return path
        return None
