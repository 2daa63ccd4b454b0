"""A KPIECE-style planner (Sucan & Kavraki 2009): a tree whose growth is steered by a grid
over a low-dimensional random projection, favouring the least explored border cells."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from manifoldgen.errors import ManifoldgenError
from manifoldgen.planning.base import Planner, PlannerSettings, Tree


@dataclass
class KPIECESettings(PlannerSettings):
    """goal_bias: probability of growing toward the goal (OMPL's 0.05 doubled: KPIECE's border-cell
    expansions walk more than RRT's steps, and at 0.05 it solved 8 of 10 pr2 tray-over runs), and
    goal_radius how far from it the target of that growth may lie (see
    :meth:`Planner._toward_goal`); border_fraction: probability of expanding a border cell (fewer
    than 2 d occupied neighbours); cells: grid cells along each of the ``dimensions`` projected axes
    (0: max(2, ceil(log2 n)))."""

    goal_bias: float = 0.1
    goal_radius: float = 1.8
    border_fraction: float = 0.9
    cells: int = 20
    dimensions: int = 0

    def check(self) -> None:
        super().check()
        if not (0 <= self.goal_bias <= 1 and 0 <= self.border_fraction <= 1 and self.goal_radius > 0
                and self.cells > 0 and self.dimensions >= 0):
            raise ManifoldgenError("KPIECE needs goal_bias and border_fraction in [0, 1], goal_radius > 0, cells > 0, "
                                   "dimensions >= 0")


class KPIECE(Planner):
    """Single tree; each iteration picks a cell (border cells first, then the less selected
    and less covered), then the node of that cell closest to a sample, and extends it toward that
    sample; with probability ``goal_bias`` it grows toward the goal instead, as RRT does."""

    name = "kpiece"
    settings_type = KPIECESettings

    def _solve(self, start, goal, deadline):
        robot, settings = self.space.robot, self.settings
        grid = _Grid(*random_projection(robot, settings.dimensions, settings.cells, self.rng))
        tree = Tree(start)
        self.trees = [tree]
        self._start_pool(self.trees, deadline)
        grid.add(0, start)
        while time.perf_counter() < deadline:
            self.iterations += 1
            first = len(tree)
            if self.rng.random() < settings.goal_bias:
                path = self._toward_goal(goal, settings.goal_radius, deadline)
            else:
                path = self._explore(tree, grid, goal)
            for i in range(first, len(tree)):
                if np.isfinite(tree.q[i, 0]):  # not cut by a failed check
                    grid.add(i, tree.q[i])
            if path is not None:
                return path
        return None

    def _explore(self, tree: Tree, grid: _Grid, goal: np.ndarray) -> np.ndarray | None:
        """Extend the node of a chosen cell closest to a sample toward it; the path when the new
        node reaches the goal, else None."""
        cell = grid.choose(self.rng, self.settings.border_fraction)
        target = self._draw()
        members = [m for m in grid.members[cell] if np.isfinite(tree.q[m, 0])]  # not cut by a failed check
        if not members:
            return None
        node = members[int(np.argmin(np.linalg.norm(tree.q[members] - target, axis=1)))]
        new = self._extend(tree, node, target)
        return None if new is None else self._reach_goal(tree, new, goal)

    def _extend(self, tree: Tree, node: int, target: np.ndarray) -> int | None:
        """Grow ``node`` toward ``target``: through the pooled sample within range of it closest to
        the target when the local planner uses stepping stones, walking when there is none."""
        origin = tree.q[node]
        steer = self.local.steer
        if self.pool is not None and np.linalg.norm(target - origin) > self.settings.range:
            self.pool.add(target[None])
            stone = self.pool.take_near(origin, target)
            if stone is None:
                self.out_of_reach += 1
                if not self.local.walks:
                    return None
                steer = self.local.walk
            else:
                target = stone
        waypoints, _ = steer(origin, target, self.settings.range)
        return tree.add(node, waypoints) if len(waypoints) else None


def random_projection(robot, dimensions: int, cells: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Random unit ``axes (d, n)`` (d = ``dimensions``, or max(2, ceil(log2 n)) when 0) and the cell size
    ``(d,)`` that cuts the joint box's extent along each axis into ``cells`` cells."""
    d = dimensions or max(2, int(np.ceil(np.log2(robot.n))))
    axes = rng.normal(size=(d, robot.n))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    return axes, np.abs(axes) @ (robot.upper - robot.lower) / cells


class _Grid:
    """Cells of size ``size (d,)`` over the projection ``axes (d, n)``: the nodes in each cell,
    how many of its 2 d neighbour cells are occupied, and how often it was chosen."""

    def __init__(self, axes: np.ndarray, size: np.ndarray):
        self.axes, self.size = axes, size
        self.members: dict[tuple[int, ...], list[int]] = {}
        self.neighbours: dict[tuple[int, ...], int] = {}
        self.picked: dict[tuple[int, ...], int] = {}

    def add(self, node: int, q: np.ndarray) -> None:
        cell = tuple(np.floor(self.axes @ q / self.size).astype(int).tolist())
        if cell not in self.members:
            around = [cell[:a] + (cell[a] + s,) + cell[a + 1:] for a in range(len(cell)) for s in (-1, 1)]
            present = [c for c in around if c in self.members]
            for c in present:
                self.neighbours[c] += 1
            self.neighbours[cell], self.members[cell], self.picked[cell] = len(present), [], 0
        self.members[cell].append(node)

    def choose(self, rng: np.random.Generator, border_fraction: float) -> tuple[int, ...]:
        """A border cell (fewer than 2 d occupied neighbours) with probability ``border_fraction``
        (when there is one), else any; weighted toward less chosen and less covered cells."""
        cells = list(self.members)
        border = [c for c in cells if self.neighbours[c] < 2 * len(c)]
        pool = border if border and rng.random() < border_fraction else cells
        weight = np.array([1.0 / ((1 + self.picked[c]) * len(self.members[c])) for c in pool])
        cell = pool[rng.choice(len(pool), p=weight / weight.sum())]
        self.picked[cell] += 1
        return cell
