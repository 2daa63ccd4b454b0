"""PRM (Kavraki et al. 1996): a roadmap of samples joined to their nearest neighbours."""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from manifoldgen.errors import ManifoldgenError
from manifoldgen.planning.base import Planner, PlannerSettings


@dataclass
class PRMSettings(PlannerSettings):
    """neighbors: closest roadmap nodes within ``radius`` (rad) a new node tries to join, with the
    local planner's connect (a walk on the manifold under ``auto``; OMPL's PRM takes the closest at
    any distance, but a long walk can take seconds, and in 6 and more dimensions the samples'
    nearest neighbours often lie beyond ``range``);
    batch: samples added between two start-goal queries; expand: expansion walks from each of the
    start's and the goal's components per batch (local planners that walk)."""

    neighbors: int = 10
    radius: float = 1.5
    batch: int = 64
    expand: int = 8

    def check(self) -> None:
        super().check()
        if self.neighbors <= 0 or self.radius <= 0 or self.batch <= 0 or self.expand < 0:
            raise ManifoldgenError("PRM needs neighbors > 0, radius > 0, batch > 0 and expand >= 0")


class PRM(Planner):
    """Roadmap with start and goal as nodes 0 and 1; a new node is joined to its nearest
    neighbours in other connected components (so the roadmap stays a forest), and the search
    stops once start and goal share a component. A path that fails the dense check loses
    its failing edge."""

    name = "prm"
    settings_type = PRMSettings

    def _solve(self, start, goal, deadline):
        self._q = np.array([start, goal])
        self._edges: dict[int, dict[int, np.ndarray]] = {0: {}, 1: {}}
        self._component = np.array([0, 1])
        self._bridged: set[tuple[int, int]] = set()  # (start-side, goal-side) node pairs walked between
        while time.perf_counter() < deadline:
            for q in self._draw_many(self.settings.batch):
                self.iterations += 1
                self._insert(q)
                if time.perf_counter() > deadline:
                    break
            for _ in range(self.settings.expand if self.local.walks else 0):
                for end in (0, 1, None):
                    if self._component[0] != self._component[1] and time.perf_counter() < deadline:
                        self._expand(end)
            while self._component[0] == self._component[1]:
                path, edges = self._path()
                report = self._accept(path)
                if report.valid:
                    return path
                self._remove(*edges[report.segment])
        return None

    def _extras(self):
        return {"roadmap": {"nodes": len(getattr(self, "_q", ())),
                            "edges": sum(len(e) for e in getattr(self, "_edges", {}).values()) // 2}}

    def _insert(self, q: np.ndarray, parent: int = -1, walked: np.ndarray | None = None) -> None:
        """Add node ``q (n,)`` (reached from node ``parent`` along the checked ``walked (K, n)``, if
        given) and join it to its nearest neighbours in other components."""
        new = len(self._q)
        gaps = np.linalg.norm(self._q - q, axis=1)
        self._q = np.concatenate([self._q, q[None]])
        self._edges[new] = {}
        self._component = np.append(self._component, new)
        if walked is not None:
            self._join(parent, new, walked)
        for other in np.argsort(gaps)[:self.settings.neighbors]:
            if gaps[other] > self.settings.radius:
                break
            if self._component[other] == self._component[new]:
                continue
            waypoints = self.local.connect(self._q[other], q)
            if waypoints is not None:
                self._join(other, new, waypoints)

    def _join(self, a: int, b: int, waypoints: np.ndarray) -> None:
        """The edge between nodes ``a`` and ``b`` along ``waypoints (K, n)`` (after ``a``, ending at ``b``)."""
        self._edges[a][b] = waypoints
        self._edges[b][a] = np.concatenate([waypoints[-2::-1], self._q[a][None]])
        self._component[self._component == self._component[b]] = self._component[a]

    def _expand(self, end: int | None) -> None:
        """Kavraki et al.'s expansion step, for the query's components, which samplers seldom reach
        (few samples lie near a given start or goal): a walk on the manifold, at most ``radius``
        long, from a random node of the component of node ``end`` toward a sample, or (``end`` None)
        from the start's component toward the goal's, between their closest nodes not tried yet;
        its end joins the roadmap."""
        if end is None:
            ours = np.flatnonzero(self._component == self._component[0])
            theirs = np.flatnonzero(self._component == self._component[1])
            gaps = np.linalg.norm(self._q[ours][:, None] - self._q[theirs][None], axis=2)
            for i, j in zip(*np.unravel_index(np.argsort(gaps, axis=None), gaps.shape)):
                node, target = int(ours[i]), int(theirs[j])
                if (node, target) not in self._bridged:
                    break
            else:
                return
            self._bridged.add((node, target))
            target = self._q[target]
        else:
            members = np.flatnonzero(self._component == self._component[end])
            node, target = members[self.rng.integers(len(members))], self._draw()
        waypoints, _ = self.local.walk(self._q[node], target, self.settings.radius)
        if len(waypoints):
            self._insert(waypoints[-1], node, waypoints)

    def _path(self) -> tuple[np.ndarray, list[tuple[int, int]]]:
        """The roadmap path from node 0 to node 1 (breadth-first: the roadmap is a forest), and
        for each of its segments the roadmap edge it lies on."""
        parent = {0: -1}
        queue = deque([0])
        while queue:
            u = queue.popleft()
            for v in self._edges[u]:
                if v not in parent:
                    parent[v] = u
                    queue.append(v)
        nodes = [1]
        while nodes[-1] != 0:
            nodes.append(parent[nodes[-1]])
        pairs = list(zip(nodes[::-1], nodes[-2::-1]))
        pieces = [self._q[:1]] + [self._edges[u][v] for u, v in pairs]
        return np.concatenate(pieces), [pair for pair in pairs for _ in self._edges[pair[0]][pair[1]]]

    def _remove(self, u: int, v: int) -> None:
        self._edges[u].pop(v, None)
        self._edges[v].pop(u, None)
        self._component = np.arange(len(self._q))
        for a in range(len(self._q)):
            for b in self._edges[a]:
                self._component[self._component == self._component[b]] = self._component[a]
