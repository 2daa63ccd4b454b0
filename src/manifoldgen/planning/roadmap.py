"""Experience: the paths a planner found, kept as a roadmap that later queries in the same space (condition and
scene) search before planning (as OMPL's Thunder keeps its solutions).

Nodes are the waypoints of earlier paths; an edge is a straight segment that passed the space's dense path check
(a path's consecutive waypoints, a new path's waypoints joined to the nearest nodes of earlier ones, a query's start
and goal joined to their nearest nodes, two each at most). A query joins start and goal to the roadmap and takes the shortest route
through it; a route is made of checked segments only, so it is valid as a whole by the same check."""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable

import numpy as np

TRIES, JOINS = 6, 2  # a query's start or goal (or a new waypoint) tries its 6 nearest nodes, joins the first 2 it can


class Roadmap:
    """Waypoints (N, n) and checked straight edges between them; ``valid(segment (2, n)) -> bool`` is the dense
    path check, ``reach`` the longest edge tried (rad)."""

    def __init__(self, n: int, valid: Callable[[np.ndarray], bool], reach: float):
        self.q = np.zeros((0, n))
        self.edges: list[dict[int, float]] = []  # node -> {neighbour: length}
        self.valid, self.reach = valid, reach
        self.checks = 0  # segments checked (the query's cost besides the search)

    def __len__(self) -> int:
        return len(self.q)

    def route(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray | None:
        """The shortest route (K, n) from ``start`` to ``goal`` through the roadmap, each segment checked (the ends
        then stay as nodes), or None when either end joins no node or the nodes they join are not connected."""
        if not len(self.q):
            return None
        first, last = self._joins(start), self._joins(goal)
        if not first or not last:
            return None
        nodes = self._shortest(first, last, goal)
        if nodes is None:
            return None
        route = np.concatenate([start[None], self.q[nodes], goal[None]])
        for q, joined in ((start, first), (goal, last)):  # the ends become nodes, joined as found
            self.q = np.concatenate([self.q, q[None]])
            self.edges.append({})
            for node, length in joined.items():
                self._link(len(self.q) - 1, node, length)
        return route

    def add(self, path: np.ndarray) -> None:
        """Keep ``path (K, n)`` (it passed the dense check): its waypoints become nodes, its segments edges, and
        each waypoint is joined to its nearest earlier nodes where that segment passes the check."""
        path = np.asarray(path, float)
        joins = [self._joins(q) if len(self.q) else {} for q in path]
        base = len(self.q)
        self.q = np.concatenate([self.q, path])
        self.edges += [{} for _ in path]
        for k in range(1, len(path)):
            self._link(base + k - 1, base + k, float(np.linalg.norm(path[k] - path[k - 1])))
        for k, joined in enumerate(joins):
            for node, length in joined.items():
                self._link(base + k, node, length)

    def _joins(self, q: np.ndarray) -> dict[int, float]:
        """The nearest nodes within ``reach`` of ``q (n,)`` whose straight segment to ``q`` passes the check, nearest
        first (:data:`TRIES` tried, the first :data:`JOINS` kept): node -> length."""
        d = np.linalg.norm(self.q - q, axis=1)
        nearest = np.argpartition(d, TRIES)[:TRIES] if len(d) > TRIES else np.arange(len(d))
        out = {}
        for node in nearest[np.argsort(d[nearest], kind="stable")]:
            if d[node] > self.reach or len(out) == JOINS:
                break
            self.checks += 1
            if d[node] == 0 or self.valid(np.stack([q, self.q[node]])):
                out[int(node)] = float(d[node])
        return out

    def _link(self, a: int, b: int, length: float) -> None:
        if a != b:
            self.edges[a][b] = self.edges[b][a] = length

    def _shortest(self, first: dict[int, float], last: dict[int, float], goal: np.ndarray) -> list[int] | None:
        """A* from the start's joins (their lengths as starting costs) to the goal's, the straight distance to
        ``goal`` as the estimate (never above an edge route's length): the node list, or None."""
        ahead = np.linalg.norm(self.q - goal, axis=1).tolist()  # Python floats: the loop below is Python's
        edges, cost = self.edges, dict(first)
        parent = {node: -1 for node in first}
        heap = [(c + ahead[node], node) for node, c in first.items()]
        heapq.heapify(heap)
        best, end, done = math.inf, -1, set()
        while heap:
            estimate, node = heapq.heappop(heap)
            if estimate >= best:
                break  # no route left can beat the best
            if node in done:
                continue
            done.add(node)
            c = cost[node]
            if node in last and c + last[node] < best:
                best, end = c + last[node], node
            for other, length in edges[node].items():
                reached = c + length
                if reached < cost.get(other, math.inf):
                    cost[other], parent[other] = reached, node
                    heapq.heappush(heap, (reached + ahead[other], other))
        if end < 0:
            return None
        nodes = [end]
        while parent[nodes[-1]] >= 0:
            nodes.append(parent[nodes[-1]])
        return nodes[::-1]
