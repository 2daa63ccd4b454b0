"""Experience: the paths a planner found, kept as a roadmap that later queries in the same space (condition and
scene) search before planning (as OMPL's Thunder keeps its solutions).

Nodes are the waypoints of earlier paths; an edge is a straight segment that passed the space's dense path check
(a path's consecutive waypoints, a new path's waypoints joined to the nearest nodes of earlier ones, a query's start
and goal joined to their nearest nodes, two each at most). A query joins start and goal to the roadmap and takes the
shortest route through it; a route is made of checked segments only, so it is valid as a whole by the same check.

A roadmap is saved to an ``.npz`` file (:meth:`Roadmap.save`, docs/file-formats.md) and read back
(:meth:`Roadmap.load`) for later queries in another process. The file is an input like any other: its meta must
name the same query space (:data:`IDENTITY`), an edge read from it is checked again the first time a route takes it,
and before the roadmap is saved every node and edge read that is unchecked still is checked, and dropped when it
fails (:meth:`Roadmap.check_read`): a file written holds only what passed the check."""

from __future__ import annotations

import heapq
import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from manifoldgen.errors import ManifoldgenError, file_reader, listed, short
from manifoldgen.io import load_npz, save_npz

TRIES, JOINS = 6, 2  # a query's start or goal (or a new waypoint) tries its 6 nearest nodes, joins the first 2 it can
NEIGHBOURS = 10  # a sample of a roadmap made from samples (Roadmap.of_samples) tries its 10 nearest nodes, as PRM's k
FORMAT_VERSION = 1
# the meta keys that say which query space a roadmap holds for (a file whose values differ is refused) -> their name
IDENTITY = {"robot_identity": "robot", "joints": "joints", "locked": "locked joints", "base_bounds": "base bounds",
            "constraint": "constraint", "tolerance": "tolerance", "condition": "condition", "scene_name": "scene",
            "scene_sha256": "scene objects (sha256)", "resolution": "check resolution"}
SAVED_KEYS = {"format_version", "kind", "reach"}  # what Roadmap.save adds to its caller's meta
ROADMAP_ARRAYS = ("nodes", "edges", "lengths")  # the arrays of a roadmap file, besides its meta
LENGTH_TOLERANCE = 1e-9  # rad: a recorded edge length against its nodes' distance


class Roadmap:
    """Waypoints (N, n) and checked straight edges between them; ``valid(segment (2, n)) -> bool`` is the dense
    path check, ``reach`` the longest edge tried (rad)."""

    def __init__(self, n: int, valid: Callable[[np.ndarray], bool], reach: float):
        self.q = np.zeros((0, n))
        self.edges: list[dict[int, float]] = []  # node -> {neighbour: length}
        self.valid, self.reach = valid, reach
        self.checks = 0  # segments checked (the query's cost besides the search)
        self.unchecked: set[tuple[int, int]] = set()  # edges (a < b) read from a file, checked when first routed
        self.unchecked_nodes = 0  # nodes 0 .. unchecked_nodes - 1 were read from a file and are not checked yet
        self.dropped = {"nodes": 0, "edges": 0}  # what was read from a file and failed its check
        self.grown = False  # nodes or edges added since it was made or read

    @classmethod
    def of_samples(cls, samples: np.ndarray, valid: Callable[[np.ndarray], bool], reach: float,
                   neighbours: int = NEIGHBOURS) -> Roadmap:
        """A PRM's roadmap (Kavraki et al. 1996) made before any query: ``samples (N, n)`` (valid states) are the
        nodes, each joined to those of its ``neighbours`` nearest within ``reach`` whose straight segment passes
        ``valid`` (each pair checked once)."""
        roadmap = cls(samples.shape[1], valid, reach)
        q = roadmap.q = np.array(samples, float)
        roadmap.edges, roadmap.grown = [{} for _ in q], True
        squares, tried = np.sum(q**2, axis=1), set()
        for a in range(len(q)):
            d = np.sqrt(np.maximum(squares + squares[a] - 2.0 * (q @ q[a]), 0.0))
            d[a] = np.inf
            near = np.argsort(d)[:neighbours]
            for b in map(int, near[d[near] <= reach]):
                if (min(a, b), max(a, b)) in tried:
                    continue
                tried.add((min(a, b), max(a, b)))
                roadmap.checks += 1
                if valid(q[[a, b]]):
                    roadmap._link(a, b, float(d[b]))
        return roadmap

    def __len__(self) -> int:
        return len(self.q)

    def edge_count(self) -> int:
        """E, the number of edges."""
        return sum(map(len, self.edges)) // 2

    def edge_array(self) -> tuple[np.ndarray, np.ndarray]:
        """The edges as ``(E, 2)`` int64 node pairs (each once, lower node first) and their ``(E,)`` lengths."""
        pairs = [(a, b, length) for a, out in enumerate(self.edges) for b, length in out.items() if a < b]
        return (np.array([p[:2] for p in pairs], np.int64).reshape(-1, 2),
                np.array([p[2] for p in pairs], float).reshape(-1))

    def check_read(self) -> None:
        """Check what was read from a file and is unchecked still: each edge by the dense check, then each node
        left without an edge (:meth:`check_lone_nodes`); what fails is dropped and counted in ``dropped``."""
        for a, b in sorted(self.unchecked):
            self.checks += 1
            if not self.valid(self.q[[a, b]]):
                del self.edges[a][b], self.edges[b][a]
                self.dropped["edges"] += 1
        self.unchecked.clear()
        self.check_lone_nodes()
        self.unchecked_nodes = 0

    def check_lone_nodes(self) -> None:
        """Check each node read from a file that has no edge as the zero-length segment from it to itself (a node
        with an edge passes or fails with it; one state each: cheap); drop those that fail, counted in ``dropped``."""
        bad = []
        for node in range(self.unchecked_nodes):
            if not self.edges[node]:
                self.checks += 1
                if not self.valid(self.q[[node, node]]):
                    bad.append(node)
        if bad:
            keep = np.ones(len(self.q), bool)
            keep[bad] = False
            number = np.cumsum(keep) - 1  # the kept nodes' new indices (a dropped node has no edge to renumber)
            self.q = self.q[keep]
            self.edges = [{int(number[b]): length for b, length in out.items()}
                          for out, kept in zip(self.edges, keep) if kept]
            self.unchecked = {(int(number[a]), int(number[b])) for a, b in self.unchecked}
            self.unchecked_nodes -= len(bad)
            self.dropped["nodes"] += len(bad)

    def save(self, path: str | Path, meta: dict) -> None:
        """Write the roadmap to ``path`` (atomic ``.npz``) after :meth:`check_read`: ``nodes (N, n)``, ``edges (E,
        2)``, ``lengths (E,)`` and ``meta`` (a JSON string): the caller's ``meta`` (the query space:
        :data:`IDENTITY`'s keys and what an outside checker needs) with ``format_version``, ``kind`` and ``reach``."""
        self.check_read()
        edges, lengths = self.edge_array()
        save_npz(path, {**meta, "format_version": FORMAT_VERSION, "kind": "roadmap", "reach": self.reach},
                 nodes=np.asarray(self.q, float), edges=edges, lengths=lengths)

    @classmethod
    @file_reader
    def load(cls, path: str | Path, valid: Callable[[np.ndarray], bool], reach: float, *,
             expect: dict | None = None) -> Roadmap:
        """The roadmap saved at ``path``, checked whole (one-line errors for another kind of file, another format,
        damaged arrays), with the dense check ``valid`` and ``reach`` of the planner that searches it; refused when
        its meta is not ``expect`` (the meta this query saves) with :data:`SAVED_KEYS`. Its edges count as unchecked
        until a route takes them or :meth:`check_read` runs, its nodes until :meth:`check_read`."""
        meta, arrays = load_npz(path, ())
        if meta.get("kind") != "roadmap":
            raise ManifoldgenError(f"{path} is not a roadmap file (its meta says kind {meta.get('kind')!r}); give a "
                                   "file written by `plan --roadmap` or Roadmap.save")
        if meta.get("format_version") != FORMAT_VERSION:
            raise ManifoldgenError(f"{path}: roadmap format {meta.get('format_version')!r} is not the one this version "
                                   f"reads ({FORMAT_VERSION}); delete it (the next query starts a new roadmap)")
        recorded = meta.get("reach")
        if isinstance(recorded, bool) or not isinstance(recorded, (int, float)) or not 0 < recorded < math.inf:
            raise ManifoldgenError(f"{path}: meta 'reach' {short(recorded)} must be a finite number > 0 (rad); the "
                                   "file was edited: delete it (the next query starts a new roadmap)")
        if expect is not None:
            _check_identity(path, meta, expect)
        nodes, edges, lengths = _arrays(path, meta, arrays)
        roadmap = cls(nodes.shape[1], valid, reach)
        roadmap.q, roadmap.unchecked_nodes = nodes, len(nodes)
        roadmap.edges = [{} for _ in nodes]
        for (a, b), length in zip(edges.tolist(), lengths.tolist()):
            roadmap._link(a, b, length)
            roadmap.unchecked.add((min(a, b), max(a, b)))
        return roadmap

    def route(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray | None:
        """The shortest route (K, n) from ``start`` to ``goal`` through the roadmap, each segment checked (the ends
        then stay as nodes, unless they are nodes already: a repeated query adds none, and its route repeats no
        waypoint), or None when either end joins no node or the nodes they join are not connected."""
        if not len(self.q):
            return None
        first, last = self._joins(start), self._joins(goal)
        if not first or not last:
            return None
        nodes = self._shortest(first, last, goal)
        while nodes is not None and not self._recheck(nodes):
            nodes = self._shortest(first, last, goal)
        if nodes is None:
            return None
        route = np.concatenate([start[None], self.q[nodes], goal[None]])
        repeated = np.all(route[1:] == route[:-1], axis=1)  # an end that is a node already
        if len(route) - repeated.sum() >= 2:
            route = route[np.r_[True, ~repeated]]
        for q, joined in ((start, first), (goal, last)):  # the ends become nodes, joined as found
            if 0.0 in joined.values():  # the end is a node already
                continue
            self.grown = True
            self.q = np.concatenate([self.q, q[None]])
            self.edges.append({})
            for node, length in joined.items():
                self._link(len(self.q) - 1, node, length)
        return route

    def add(self, path: np.ndarray) -> None:
        """Keep ``path (K, n)`` (it passed the dense check): its waypoints become nodes, its segments edges, and
        each waypoint is joined to its nearest earlier nodes where that segment passes the check."""
        self.grown = True
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

    def _recheck(self, nodes: list[int]) -> bool:
        """Check the unchecked edges along the route ``nodes``: True when all pass; else the first that fails is
        removed (False: search again)."""
        for a, b in zip(nodes, nodes[1:]):
            edge = (min(a, b), max(a, b))
            if edge not in self.unchecked:
                continue
            self.checks += 1
            self.unchecked.discard(edge)
            if not self.valid(self.q[[a, b]]):
                del self.edges[a][b], self.edges[b][a]
                self.dropped["edges"] += 1
                return False
        return True

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


def _check_identity(path: str | Path, meta: dict, expect: dict) -> None:
    """Refuse a roadmap whose ``meta`` is not the one this query writes (``expect``, less what :meth:`Roadmap.save`
    adds): another query space (the :data:`IDENTITY` keys first), or copies of the task, condition or scene that
    were edited, or keys of its own; naming the first few differences."""
    wanted = json.loads(json.dumps(expect))
    keys = [*(key for key in IDENTITY if key in wanted), *sorted(set(wanted) - set(IDENTITY))]
    differences = [line for key in keys if meta.get(key) != wanted[key]
                   for line in _differences(key, meta.get(key), wanted[key])]
    differences += [f"key {key!r} of its own" for key in sorted(set(meta) - set(wanted) - SAVED_KEYS)]
    if differences:
        raise ManifoldgenError(f"{path} holds a roadmap for another query: {listed(differences)}; give this query "
                               f"another roadmap file (or delete {path} to start a new one)")


def _differences(key: str, made, wanted) -> list[str]:
    """``key``'s values in the file and in this query (of an object: one line per field that differs)."""
    name = IDENTITY.get(key, key)
    if isinstance(made, dict) and isinstance(wanted, dict):
        if made.get("type") != wanted.get("type"):  # another kind of object: its other fields say nothing more
            return [_difference(f"{name} type", made.get("type"), wanted.get("type"))]
        return [_difference(f"{name} {field}", made.get(field), wanted.get(field))
                for field in sorted({*made, *wanted}) if made.get(field) != wanted.get(field)]
    return [_difference(name, made, wanted)]


def _difference(name: str, made, wanted) -> str:
    """``name`` with both values when they are short (a sha256: its first 12 digits), else that they differ."""
    shown = [json.dumps(v[:12] if isinstance(v, str) and len(v) == 64 else v) for v in (made, wanted)]
    if max(map(len, shown)) > 30:
        return f"{name} differs"
    return f"{name} {shown[0]} (the file) vs {shown[1]} (this query)"


def _arrays(path: str | Path, meta: dict, arrays: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The file's ``nodes (N, n)`` float64, ``edges (E, 2)`` int and ``lengths (E,)`` float64, checked: finite float64
    nodes as wide as the meta's ``joints``, edges between distinct nodes, lengths their nodes' distances; no other
    array."""
    fix = "the file is damaged or was edited: delete it (the next query starts a new roadmap)"
    missing = [k for k in ROADMAP_ARRAYS if k not in arrays]
    if missing:
        raise ManifoldgenError(f"{path}: no {', '.join(missing)} array; {fix}")
    extra = sorted(set(arrays) - set(ROADMAP_ARRAYS))
    if extra:
        raise ManifoldgenError(f"{path}: unknown array {short(extra[0])} (a roadmap file holds only 'nodes', 'edges' "
                               f"and 'lengths'); {fix}")
    nodes, edges, lengths = arrays["nodes"], arrays["edges"], arrays["lengths"]
    n = len(meta["joints"]) if isinstance(meta.get("joints"), list) else -1
    if nodes.dtype != np.float64 or nodes.ndim != 2 or nodes.shape[1] != n or not np.isfinite(nodes).all():
        raise ManifoldgenError(f"{path}: 'nodes' must be finite float64 numbers of shape (N, {n}) (the meta's "
                               f"joints), got {nodes.dtype} {nodes.shape}; {fix}")
    if edges.dtype.kind not in "iu" or edges.ndim != 2 or edges.shape[1] != 2 or lengths.shape != (len(edges),) \
            or lengths.dtype.kind != "f":
        raise ManifoldgenError(f"{path}: 'edges' must be (E, 2) integers and 'lengths' (E,) numbers, got "
                               f"{edges.dtype} {edges.shape} and {lengths.dtype} {lengths.shape}; {fix}")
    if lengths.dtype != np.float64:
        raise ManifoldgenError(f"{path}: 'lengths' must be float64 (what Roadmap.save writes), got {lengths.dtype}; "
                               f"{fix}")
    if len(edges) and (edges.min() < 0 or edges.max() >= len(nodes) or np.any(edges[:, 0] == edges[:, 1])):
        raise ManifoldgenError(f"{path}: 'edges' must join two distinct nodes of the {len(nodes)}; {fix}")
    if np.any(edges[:, 0] > edges[:, 1]) or len(np.unique(edges, axis=0)) != len(edges):
        raise ManifoldgenError(f"{path}: 'edges' must list each edge once, its lower node first (as Roadmap.save "
                               f"writes them); {fix}")
    nodes = np.asarray(nodes, float)
    distance = np.linalg.norm(nodes[edges[:, 1]] - nodes[edges[:, 0]], axis=1)
    if not np.all(np.abs(lengths - distance) <= LENGTH_TOLERANCE):
        raise ManifoldgenError(f"{path}: 'lengths' are not the distances between the nodes of each edge; {fix}")
    return nodes, edges.astype(np.int64), np.asarray(lengths, float)
