"""RRT (LaValle 1998): one tree from the start, grown toward samples and, now and then, the goal."""

from __future__ import annotations

import time
from dataclasses import dataclass


from manifoldgen.errors import ManifoldgenError
from manifoldgen.planning.base import Planner, PlannerSettings, Tree


@dataclass
class RRTSettings(PlannerSettings):
    """goal_bias: probability of growing toward the goal instead of a sample."""

    goal_bias: float = 0.05

    def check(self) -> None:
        super().check()
        if not 0 <= self.goal_bias <= 1:
            raise ManifoldgenError(f"goal_bias must be in [0, 1], got {self.goal_bias}")


class RRT(Planner):
    """Single-tree RRT with goal bias; a node within ``range`` of the goal tries to reach it."""

    name = "rrt"
    settings_type = RRTSettings

    def _solve(self, start, goal, deadline):
        tree = Tree(start)
        self.trees = [tree]
        self._start_pool(self.trees, deadline)
        while time.perf_counter() < deadline:
            self.iterations += 1
            to_goal = self.rng.random() < self.settings.goal_bias
            new = self._grow(0, goal if to_goal else self._draw(), keep=not to_goal)
            path = None if new is None else self._reach_goal(tree, new, goal)
            if path is not None:
                return path
        return None
