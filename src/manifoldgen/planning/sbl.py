"""SBL (Sánchez & Latombe 2001): single-query, bidirectional, lazy collision checking.

Two trees, rooted at the start and the goal, take turns to grow. A tree picks a cell of a grid
over a random low-dimensional projection with probability inversely proportional to the nodes in
it (OMPL's way of favouring sparse regions), one of its nodes at random, and adds a node near it.
That edge is not checked. When the new node falls in a cell the other tree occupies, it is bridged
to the other tree's node in that cell closest to it (OMPL's rule), and else to the other tree's
nearest node if that lies within ``bridge`` (the 2001 paper's rule: the trees seldom share a cell
of the grid on a manifold of 6 and more dimensions, where the cells' projection mixes it with the
joints it does not span), and only then are the edges of the path start .. bridge .. goal
checked, in order from the start, each with the local planner (a chord that leaves the manifold becomes a projected walk under ``auto`` and
``project``). An edge that passes is never checked again. A bridge that fails is dropped. A tree
edge that fails is removed, and the nodes beyond it, still joined to the other tree through the
bridge, move to that tree, as in the 2001 paper (OMPL's SBL deletes them instead; keeping them
solved far more of the panda maze's queries). The path that passes goes through the space's dense
validation like every planner's, and a segment that fails it is handled the same way.

"Near a node", with a sampler that puts its samples on the manifold: a random perturbation of a
node leaves the manifold, so the new node is one of the sampler's samples. The planner draws a
sample (the direction; it joins the pool) and takes the pooled sample within ``range`` of the node
that lies closest to it, as the other tree planners steer through stepping stones; the edge to it
stays unchecked. Where no pooled sample is within range of the node, the node walks toward the
drawn sample on the manifold for at most ``range``, as it always does with the ``project`` local
planner (no stepping stones). A walk is checked as it goes, so its edges are born checked. The pool
grows by the one drawn sample per iteration (drawing batches for a tree with no sample in reach, as
RRT-Connect does, spent half of SBL's time on samples that landed far from both trees).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from manifoldgen.errors import ManifoldgenError
from manifoldgen.planning.base import Planner, PlannerSettings, Tree
from manifoldgen.planning.kpiece import random_projection


@dataclass
class SBLSettings(PlannerSettings):
    """cells: grid cells along each of the ``dimensions`` projected axes (0: max(2, ceil(log2 n)))
    of the density grid that picks the node to expand; bridge: distance (rad) within which a new
    node outside the other tree's cells is bridged to that tree's nearest node."""

    cells: int = 20
    dimensions: int = 0
    bridge: float = 0.6

    def check(self) -> None:
        super().check()
        if self.cells <= 0 or self.dimensions < 0 or self.bridge < 0:
            raise ManifoldgenError(f"SBL needs cells > 0, dimensions >= 0 and bridge >= 0, got {self.cells}, "
                                   f"{self.dimensions}, {self.bridge}")


class SBL(Planner):
    """Bidirectional lazy planner: trees grown without checking edges, edges checked only on a
    candidate path from start to goal (see the module doc)."""

    name = "sbl"
    settings_type = SBLSettings

    def _solve(self, start, goal, deadline):
        settings = self.settings
        self._plant(start, goal, *random_projection(self.space.robot, settings.dimensions, settings.cells, self.rng))
        self._start_pool(self.trees, deadline)
        while time.perf_counter() < deadline:
            self.iterations += 1
            side = self.iterations % 2
            new = self._expand(side, self._grids[side].choose(self.rng))
            if new is None:
                continue
            path = self._bridge(side, new)
            if path is not None:
                return path
        return None

    def _plant(self, start: np.ndarray, goal: np.ndarray, axes: np.ndarray, size: np.ndarray) -> None:
        """The two trees and their density grids (cells of ``size (d,)`` over the projection ``axes (d, n)``),
        no edge checked yet."""
        self._checked = self._removed = 0
        self._via: list[dict[int, np.ndarray]] = [{}, {}]  # checked edges: node -> waypoints (K, n) ending at it
        self.trees = [Tree(start), Tree(goal)]
        self._grids = [_Grid(axes, size, tree) for tree in self.trees]

    def _extras(self):
        """Lazy checks of the query: edges (and bridges) checked, and removed because they failed."""
        return {"lazy": {"edges_checked": self._checked, "edges_removed": self._removed}} if self.trees else {}

    def _expand(self, k: int, node: int) -> int | None:
        """Add a node near ``node`` of tree ``k`` (see the module doc): the new node or None."""
        tree, origin = self.trees[k], self.trees[k].q[node]
        target = self._draw()
        if self.pool is not None:
            self.pool.add(target[None])
            stone = self.pool.take_near(origin, target)
            if stone is not None:
                new = tree.add(node, stone[None])
                self._grids[k].add(new)
                return new
            self.out_of_reach += 1
            if not self.local.walks:
                return None
        waypoints, _ = self.local.walk(origin, target, self.settings.range)
        if not len(waypoints):
            return None
        first = len(tree)
        new = tree.add(node, waypoints)
        for i in range(first, new + 1):
            self._via[k][i] = tree.q[i:i + 1].copy()
            self._grids[k].add(i)
        return new

    def _bridge(self, k: int, new: int) -> np.ndarray | None:
        """Bridge node ``new`` of tree ``k`` to the closest node of the other tree in its cell, or
        else to the other tree's nearest node when that lies within ``bridge``; check the path
        through the bridge lazily, then densely: the path or None."""
        other, q = self.trees[1 - k], self.trees[k].q[new]
        members = self._grids[1 - k].cells.get(self._grids[1 - k].cell(q))
        if members:
            near = members[int(np.argmin(np.linalg.norm(other.q[members] - q, axis=1)))]
        else:
            near = other.nearest(q)
            if np.linalg.norm(other.q[near] - q) > self.settings.bridge:
                return None
        ends = (new, near) if k == 0 else (near, new)
        edges = [(0, i) for i in self.trees[0].branch(ends[0])[1:]] + [None] + \
                [(1, i) for i in self.trees[1].branch(ends[1])[:0:-1]]
        bridge = None  # waypoints (K, n) from ends[0] to ends[1], once checked
        for edge in edges:
            if edge is None:
                self._checked += 1
                bridge = self.local.connect(self.trees[0].q[ends[0]], self.trees[1].q[ends[1]])
                if bridge is None:
                    self._removed += 1
                    return None
                bridge = bridge.copy()  # not a view of a node that a cut may remove
            elif not self._check(*edge):
                self._cut(*edge, ends, bridge)
                return None
        pieces, owners = [self.trees[0].q[:1]], []
        for edge in edges:
            if edge is None:
                via = bridge
            elif edge[0] == 0:
                via = self._via[0][edge[1]]
            else:  # walked from the node back to its parent
                tree = self.trees[1]
                via = _reverse(self._via[1][edge[1]], tree.q[tree.parent[edge[1]]])
            pieces.append(via)
            owners += [edge] * len(via)
        path = np.concatenate(pieces)
        report = self._accept(path)
        if report.valid:
            return path
        if owners[report.segment] is not None:
            self._cut(*owners[report.segment], ends, bridge)
        return None

    def _check(self, k: int, i: int) -> bool:
        """Check the edge into node ``i`` of tree ``k`` once (remembering its waypoints)."""
        if i in self._via[k]:
            return True
        tree = self.trees[k]
        self._checked += 1
        waypoints = self.local.connect(tree.q[tree.parent[i]], tree.q[i])
        if waypoints is not None:
            self._via[k][i] = waypoints.copy()  # not a view of a node that a cut may remove
        return waypoints is not None

    def _cut(self, k: int, i: int, ends: tuple[int, int], bridge: np.ndarray | None) -> None:
        """Remove the failed edge into node ``i`` of tree ``k``, which lies on the path to the
        bridge end ``ends[k]``: the nodes grown from ``i`` stay connected to the other tree through
        the bridge, so they move there (Sánchez & Latombe's split), the bridge end first, then
        the path up to ``i`` reversed, then the rest in order, their checked edges kept."""
        self._removed += 1
        src, dst, via, dst_via = self.trees[k], self.trees[1 - k], self._via[k], self._via[1 - k]
        inside = np.zeros(src.size, dtype=bool)  # the live nodes grown from i
        inside[i] = True
        for j in range(i + 1, src.size):
            inside[j] = inside[src.parent[j]]
        inside &= np.isfinite(src.q[:src.size, 0])
        up = src.branch(ends[k])
        up = up[up.index(i):][::-1]  # bridge end .. i
        moved = {up[0]: dst.add(ends[1 - k], src.q[up[0]][None])}
        if bridge is not None:
            dst_via[moved[up[0]]] = bridge if k == 1 else _reverse(bridge, src.q[up[0]])
        for child, parent in zip(up[1:], up[:-1]):
            moved[child] = dst.add(moved[parent], src.q[child][None])
            if parent in via:
                dst_via[moved[child]] = _reverse(via[parent], src.q[child])
        for j in np.flatnonzero(inside):
            if j not in moved:
                moved[j] = dst.add(moved[src.parent[j]], src.q[j][None])
                if j in via:
                    dst_via[moved[j]] = via[j]
        src.kill(i)
        self._grids[k].prune()
        for j in moved.values():
            self._grids[1 - k].add(j)


def _reverse(waypoints: np.ndarray, parent: np.ndarray) -> np.ndarray:
    """The waypoints (K, n) of an edge from ``parent (n,)`` to its last row, walked back: from the
    last row to ``parent``."""
    return np.concatenate([waypoints[-2::-1], parent[None]])


class _Grid:
    """The live nodes of ``tree`` by cell of size ``size (d,)`` over the projection ``axes (d, n)``."""

    def __init__(self, axes: np.ndarray, size: np.ndarray, tree: Tree):
        self.axes, self.size, self.tree = axes, size, tree
        self.cells: dict[tuple[int, ...], list[int]] = {}
        self.add(0)

    def cell(self, q: np.ndarray) -> tuple[int, ...]:
        """The cell of ``q (n,)``."""
        return tuple(np.floor(self.axes @ q / self.size).astype(int).tolist())

    def add(self, node: int) -> None:
        self.cells.setdefault(self.cell(self.tree.q[node]), []).append(node)

    def prune(self) -> None:
        """Forget the nodes removed from the tree (and the cells left empty)."""
        alive = np.isfinite(self.tree.q[:self.tree.size, 0])
        kept = ((cell, [i for i in nodes if alive[i]]) for cell, nodes in self.cells.items())
        self.cells = {cell: nodes for cell, nodes in kept if nodes}

    def choose(self, rng: np.random.Generator) -> int:
        """A node: its cell drawn with probability inversely proportional to the nodes in it, the
        node uniformly in the cell."""
        members = list(self.cells.values())
        weight = 1.0 / np.array([len(m) for m in members])
        nodes = members[rng.choice(len(members), p=weight / weight.sum())]
        return nodes[rng.integers(len(nodes))]
