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
    """neighbors: closest roadmap nodes (within ``range``) a new node tries to join;
    batch: samples added between two start-goal queries."""

    neighbors: int = 10
    batch: int = 64

    def check(self) -> None:
        super().check()
        if self.neighbors <= 0 or self.batch <= 0:
            raise ManifoldgenError("PRM needs neighbors > 0 and batch > 0")


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
        while time.perf_counter() < deadline:
            for q in self._draw_many(self.settings.batch):
                self.iterations += 1
                self._insert(q)
                if time.perf_counter() > deadline:
                    break
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

    def _insert(self, q: np.ndarray) -> None:
        new = len(self._q)
        gaps = np.linalg.norm(self._q - q, axis=1)
        self._q = np.concatenate([self._q, q[None]])
        self._edges[new] = {}
        self._component = np.append(self._component, new)
        for other in np.argsort(gaps)[:self.settings.neighbors]:
            if gaps[other] > self.settings.range:
                break
            if self._component[other] == self._component[new]:
                continue
            waypoints = self.local.connect(self._q[other], q)
            if waypoints is None:
                continue
            self._edges[other][new] = waypoints
            self._edges[new][other] = np.concatenate([waypoints[-2::-1], self._q[other][None]])
            self._component[self._component == self._component[new]] = self._component[other]

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
