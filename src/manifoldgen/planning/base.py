"""The planner contract, shared settings, and the tree every tree planner grows.

A planner works in a :class:`~manifoldgen.space.ConstrainedSpace` (constraint, condition,
collision checker, validation settings) with a :class:`Sampler` and a local planner;
``solve(start, goal, time_limit)`` returns a :class:`PlanResult` whose path passed the
space's dense :meth:`~manifoldgen.space.ConstrainedSpace.validate_path`. A candidate path that
fails that check loses its offending edge (and everything grown from it) and the search goes
on. An unsolved result says why in its ``extras`` (see :meth:`PlanResult.why`).
"""

from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from manifoldgen.errors import ManifoldgenError, SamplerFailed
from manifoldgen.planning.local import DEFAULT_LOCAL, make_local
from manifoldgen.planning.result import PlanResult, path_length
from manifoldgen.planning.roadmap import Roadmap
from manifoldgen.planning.smoothing import relax, shortcut
from manifoldgen.sampling import Sampler, cost_scale
from manifoldgen.space import REASONS, ConstrainedSpace, PathReport

TIME_LIMITS = (1e-3, 86_400.0)  # s: a query's time limit (beyond a day, the search's clock arithmetic overflows)
SMOOTH_SHORTCUTS = 50  # PlannerSettings.shortcut under `plan --smooth` (docs/benchmarks.md, "Shorter paths")
# each numeric planner setting's range: a resolution finer than 1e-4 rad or a pool of millions of rows would
# only exhaust memory
LIMITS = {"range": (1e-4, 100.0), "resolution": (1e-4, 10.0), "step": (1e-4, 100.0), "pool": (0, 10**6),
          "pool_batch": (1, 10**6), "candidates": (1, 10**4), "shortcut": (0, 10**6), "informed": (0, 100)}
INFORMED_BUDGET = 2.0  # an informed search may take this many times the first search's time

@dataclass
class PlannerSettings:
    """Knobs every planner shares.

    range: longest extension (rad, joint-space Euclidean); resolution: spacing of the checked
    states along a straight segment while planning (the final check of a path uses the space's
    finer ``ValidationSettings.resolution``); step: longest distance between projected states
    (walks, halved where a segment fails); partial: a blocked straight extension keeps its valid
    part; pool / pool_batch: stepping stones drawn up front / whenever a tree has none within
    range (see :class:`SamplePool`), in rows of a sampler whose row costs at most
    :data:`~manifoldgen.sampling.REFERENCE_ROW_COST` multiply-adds; a dearer model's rows are fewer in
    proportion (:meth:`Planner.pool_rows`); candidates: stepping stones checked (in one batch) per
    extension; shortcut: attempts to shorten a found path within the time limit (each new stretch
    kept only when shorter and valid by the dense path check, :mod:`manifoldgen.planning.smoothing`;
    0: the path as found, as OMPL's planners give it; ``plan --smooth``: :data:`SMOOTH_SHORTCUTS`); informed:
    searches after the first path, each drawing only rows a shorter path could visit (the informed set of the
    best length so far, no pool drawn ahead) and shortened alike, each within :data:`INFORMED_BUDGET` times the
    first search's time; the shortest path is kept (0: the first path); reuse: keep the paths found as a roadmap
    that later queries of this planner (its condition and scene) search first
    (:mod:`manifoldgen.planning.roadmap`; a route found there is not shortened).
    """

    range: float = 0.6
    resolution: float = 0.05
    step: float = 0.4
    partial: bool = True
    pool: int = 2048
    pool_batch: int = 256
    candidates: int = 8
    shortcut: int = 0
    informed: int = 0
    reuse: bool = False

    def check(self) -> None:
        """A one-line error naming the first setting of the wrong type or outside its range (:data:`LIMITS`)."""
        for key, (low, high) in LIMITS.items():
            value, default = getattr(self, key), getattr(type(self), key)
            whole = isinstance(default, int)
            if isinstance(value, bool) or not isinstance(value, int if whole else (int, float)) \
                    or not math.isfinite(value) or not low <= value <= high:
                kind = "a whole number" if whole else "a number"
                raise ManifoldgenError(f"planner setting {key} must be {kind} in [{low:g}, {high:g}], got {value!r}; "
                                       f"e.g. {key}={default}")
        for key in ("partial", "reuse"):
            if not isinstance(getattr(self, key), bool):
                raise ManifoldgenError(f"planner setting {key} must be true or false, got {getattr(self, key)!r}")


def check_time_limit(time_limit: float, what: str = "time limit") -> None:
    """Refuse a query's time limit outside :data:`TIME_LIMITS` (NaN included), in one line naming ``what``."""
    low, high = TIME_LIMITS
    if not low <= time_limit <= high:
        raise ManifoldgenError(f"{what} must be from {low:g} to {high:g} seconds, got {time_limit!r}")


class Tree:
    """Configurations (N, n) with parent links; each edge is a straight, checked segment."""

    def __init__(self, root: np.ndarray, capacity: int = 512):
        self.q = np.full((capacity, len(root)), np.inf)
        self.q[0] = root
        self.parent = np.full(capacity, -1, dtype=int)
        self.size = 1

    def __len__(self) -> int:
        return self.size

    def add(self, parent: int, waypoints: np.ndarray) -> int:
        """Append ``waypoints (K, n)`` as a chain below ``parent``; returns the last node."""
        for q in waypoints:
            if self.size == len(self.q):
                self.q = np.concatenate([self.q, np.full_like(self.q, np.inf)])
                self.parent = np.concatenate([self.parent, np.full_like(self.parent, -1)])
            self.q[self.size], self.parent[self.size] = q, parent
            parent = self.size
            self.size += 1
        return parent

    def nearest(self, q: np.ndarray) -> int:
        """Index of the live node closest to ``q (n,)``."""
        diff = self.q[:self.size] - q
        return int(np.argmin(np.einsum("ij,ij->i", diff, diff)))

    def nearest_many(self, q: np.ndarray) -> np.ndarray:
        """(B,) indices of the live nodes closest to each row of ``q (B, n)``."""
        nodes = self.q[:self.size]
        live = np.flatnonzero(np.isfinite(nodes[:, 0]))
        d2 = np.einsum("ij,ij->i", nodes[live], nodes[live])[None] - 2 * q @ nodes[live].T
        return live[np.argmin(d2, axis=1)]

    def branch(self, i: int) -> list[int]:
        """Node indices from the root to ``i``."""
        out = [i]
        while self.parent[out[-1]] >= 0:
            out.append(int(self.parent[out[-1]]))
        return out[::-1]

    def kill(self, i: int) -> None:
        """Remove node ``i`` and its descendants from nearest-neighbour queries."""
        dead = np.zeros(self.size, dtype=bool)
        dead[i] = True
        for j in range(i + 1, self.size):
            dead[j] = dead[self.parent[j]]
        self.q[:self.size][dead] = np.inf


class Planner(ABC):
    """Plans in ``space`` with samples from ``sampler`` (at the same condition) and the local
    planner named ``local`` (see :mod:`manifoldgen.planning.local`)."""

    name: ClassVar[str]
    settings_type: ClassVar[type[PlannerSettings]] = PlannerSettings

    def __init__(self, space: ConstrainedSpace, sampler: Sampler, *, local: str = DEFAULT_LOCAL, seed: int = 0,
                 settings: PlannerSettings | None = None):
        self.settings = self.settings_type() if settings is None else settings
        if not isinstance(self.settings, self.settings_type):
            raise ManifoldgenError(f"{self.name} takes {self.settings_type.__name__}, got "
                                   f"{type(self.settings).__name__}")
        self.settings.check()
        if sampler is None:
            raise ManifoldgenError(f"{self.name} needs a sampler (uniform, project, pg:DATASET or MODEL:DIR)")
        if not np.array_equal(sampler.space.y, space.y):
            raise ManifoldgenError(f"the sampler serves condition {sampler.space.y.tolist()}, the planner "
                                   f"{space.y.tolist()}; make both for the same condition")
        self.space, self.sampler = space, sampler
        self.local = make_local(local, space, resolution=self.settings.resolution, partial=self.settings.partial,
                                step=self.settings.step)
        self.rng = np.random.default_rng(seed)
        self.iterations = self.samples = self.rejected = self.out_of_reach = 0
        self.trees: list[Tree] = []
        self.pool: SamplePool | None = None
        self._goal_gap = np.inf  # the closest a node of a single tree came to the goal
        self.roadmap = Roadmap(space.n, self._segment_valid, self.settings.range) if self.settings.reuse else None

    # ---------------------------------------------------------------- the contract
    def solve(self, start: np.ndarray, goal: np.ndarray, time_limit: float) -> PlanResult:
        """Plan from ``start (n,)`` to ``goal (n,)`` within ``time_limit`` seconds."""
        check_time_limit(time_limit)
        start, goal = (self._query_state(q, what) for q, what in ((start, "start"), (goal, "goal")))
        before = self.sampler.stats.to_dict()
        counts, projections = self.space.counts(), self.local.projections
        self.iterations = self.samples = self.rejected = self.out_of_reach = 0
        self.trees, self.pool, self._goal_gap = [], None, np.inf
        began = time.perf_counter()
        failure = ""
        self.found_length, self.shortcuts, self.relaxed = np.nan, 0, 0
        self.informed_lengths: list[float | None] = []
        checks = self.roadmap.checks if self.roadmap is not None else 0
        path = self.roadmap.route(start, goal) if self.roadmap is not None else None
        if path is not None and time.perf_counter() > began + time_limit:  # a route answers only within the limit
            path, failure = None, f"the time limit ({time_limit:g} s) passed while the roadmap's route was checked"
        routed = path is not None
        begin_query = getattr(self.sampler, "begin_query", None)  # a model sampler measures its gaps at the ends
        note = begin_query(start, goal) if begin_query and not routed and not failure else ""
        try:
            if path is None and not failure:
                path = self._direct(start, goal)
            if path is None and not failure:
                path = self._solve(start, goal, began + time_limit)
                if path is not None:
                    path = self._shorten(path, began + time_limit)
                    path = self._informed(path, start, goal, began, began + time_limit)
            if path is not None and not routed and self.roadmap is not None:
                self.roadmap.add(path)
        except SamplerFailed as exc:
            path, failure = None, str(exc)
        elapsed = time.perf_counter() - began
        after = self.sampler.stats.to_dict()
        sampler = {k: after[k] - before[k] for k in after}
        now = self.space.counts()
        rejected = {reason: now["stopped"][reason] - counts["stopped"][reason] for reason in REASONS}
        extras = {"local": self.local.name, "resolution": self.local.resolution, "sampler": sampler,
                  "nodes": [len(t) for t in self.trees], "rejected": {**rejected, "range": self.out_of_reach},
                  "rejected_paths": self.rejected, "evaluations": now["evaluations"] - counts["evaluations"],
                  "collision_checks": now["collision_checks"] - counts["collision_checks"], **self._extras()}
        if path is not None and self.settings.shortcut and not routed:
            extras.update(shortcuts=self.shortcuts, relaxed=self.relaxed, found_length=self.found_length)
        if self.informed_lengths:
            extras["informed"] = self.informed_lengths
        if self.roadmap is not None:
            extras["roadmap"] = {"routed": routed, "nodes": len(self.roadmap), "edges": self.roadmap.edge_count(),
                                 "checks": self.roadmap.checks - checks}
        if failure:
            extras["failure"] = failure
        if note:
            extras["sampler_note"] = note
        path = np.zeros((0, len(start))) if path is None else path
        return PlanResult(len(path) > 0, path, elapsed, self.iterations, self.samples,
                          self.local.projections - projections + sampler["refined"], self.name,
                          path_length(path), extras)

    def load_roadmap(self, path: str | Path, meta: dict) -> None:
        """Search the roadmap saved at ``path`` from the next query on, in place of this planner's (``reuse`` on);
        refused when its meta names another query space than ``meta`` (see
        :meth:`~manifoldgen.planning.roadmap.Roadmap.load`)."""
        self._check_reuse()
        self.roadmap = Roadmap.load(path, self._segment_valid, self.settings.range, expect=meta)

    def roadmap_of(self, samples: np.ndarray) -> None:
        """Search a PRM's roadmap made now from ``samples (N, n)`` (valid states of this planner's space, e.g. a
        model's) from the next query on, in place of this planner's (``reuse`` on; see
        :meth:`~manifoldgen.planning.roadmap.Roadmap.of_samples`)."""
        self._check_reuse()
        self.roadmap = Roadmap.of_samples(np.asarray(samples, float), self._segment_valid, self.settings.range)

    def _check_reuse(self) -> None:
        """A one-line error unless this planner keeps a roadmap (``reuse`` on)."""
        if self.roadmap is None:
            raise ManifoldgenError(f"{self.name}: a roadmap is searched only with reuse on; make the planner with "
                                   "settings reuse=True")

    @abstractmethod
    def _solve(self, start: np.ndarray, goal: np.ndarray, deadline: float) -> np.ndarray | None:
        """A path (K, n) that passed :meth:`_accept`, or None at the deadline."""

    def _segment_valid(self, segment: np.ndarray) -> bool:
        """Whether ``segment (2, n)`` passes the dense path check (the roadmap's edges)."""
        return self.space.validate_path(segment).valid

    def _shorten(self, path: np.ndarray, deadline: float) -> np.ndarray:
        """``path (K, n)`` after ``settings.shortcut`` shortcut attempts and a relaxation until ``deadline``; sets
        ``found_length`` (before them), ``shortcuts`` and ``relaxed`` (kept)."""
        self.found_length = path_length(path)
        if not self.settings.shortcut:
            return path
        shorter, self.shortcuts = shortcut(path, self.local, attempts=self.settings.shortcut,
                                           time_limit=max(deadline - time.perf_counter(), 0.0))
        taut, self.relaxed = relax(shorter, self.local, time_limit=max(deadline - time.perf_counter(), 0.0))
        return taut

    def _informed(self, path: np.ndarray, start: np.ndarray, goal: np.ndarray, began: float,
                  deadline: float) -> np.ndarray:
        """``path (K, n)`` or a shorter one: ``settings.informed`` more searches, each with a fresh tree and the
        sampler restricted to the informed set of the best length so far (:meth:`Sampler.restrict`), shortened as
        the first, within :data:`INFORMED_BUDGET` times the first search's time (and ``deadline``), until one finds
        none; books the length of the first path and of each search's (None: none found) in ``informed_lengths``."""
        if not self.settings.informed:
            return path
        budget = INFORMED_BUDGET * (time.perf_counter() - began)
        first = (self.found_length, self.shortcuts, self.relaxed)
        self.informed_lengths = [path_length(path)]
        for _ in range(self.settings.informed):
            now = time.perf_counter()
            if now >= deadline:
                break
            self.trees, self.pool, self._goal_gap = [], None, np.inf
            self.sampler.restrict(start, goal, path_length(path))
            try:
                found = self._solve(start, goal, min(deadline, now + budget))
                found = self._shorten(found, min(deadline, now + budget)) if found is not None else None
            except SamplerFailed:  # too few rows inside the informed set: the search would starve
                found = None
            finally:
                self.sampler.unrestrict()
            self.informed_lengths.append(path_length(found) if found is not None else None)
            if found is None:
                break  # the next search would draw from the same set
            if path_length(found) < path_length(path):
                path = found
        self.found_length, self.shortcuts, self.relaxed = first  # the first search's, as the extras say
        return path

    def _extras(self) -> dict:
        return {}

    def _query_state(self, q: np.ndarray, what: str) -> np.ndarray:
        """The start or goal ``q (n,)`` as floats, checked by the space's rule (a clear error when invalid)."""
        return self.space.check_query_state(q, what)

    # ---------------------------------------------------------------- helpers
    def _direct(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray | None:
        waypoints = self.local.connect(start, goal)
        if waypoints is None:
            return None
        path = np.concatenate([start[None], waypoints])
        return path if self._accept(path).valid else None

    def _start_pool(self, trees: list[Tree], deadline: float) -> None:
        """Stepping stones for local planners that use them (drawn batch by batch until the
        deadline at the latest); ``project`` steers toward any target."""
        if not self.local.stones:
            self.pool = None
            return
        pool, batch = self.pool_rows()
        self.pool = SamplePool(self._draw_many, trees, self._stone_radius(), batch)
        for _ in range(0, pool, batch):
            if time.perf_counter() > deadline:
                break
            self.pool.draw(batch)

    def pool_rows(self) -> tuple[int, int]:
        """(pool, pool_batch) in the sampler's rows: the settings' scaled by its
        :func:`~manifoldgen.sampling.cost_scale` (the same decode budget: a whole-body model's rows cost ten
        times the panda's, and most pooled rows are never used). An informed search draws no pool ahead: its
        sampler keeps a small share of the rows it decodes, so a pool filled ahead would cost many times its rows."""
        scale = cost_scale(self.sampler)
        pool = 0 if self.sampler.informed is not None else self.settings.pool
        return round(pool * scale), max(1, round(self.settings.pool_batch * scale))

    def _stone_radius(self) -> float:
        """How close to a tree's node a pooled sample must lie to be one of its stepping stones (rad)."""
        return self.settings.range

    def _grow(self, k: int, target: np.ndarray, keep: bool = True) -> int | None:
        """Extend tree ``k`` toward ``target`` from its nearest node: the new node or None.

        With the pool a target out of range is reached for through the pool (see :meth:`_far`;
        the target joins the pool when ``keep``); when no pooled sample lies within range of the
        tree and that did not help, the pool draws a batch."""
        tree = self.trees[k]
        near = tree.nearest(target)
        if self.pool is None or np.linalg.norm(target - tree.q[near]) <= self.settings.range:
            waypoints, _ = self.local.steer(tree.q[near], target, self.settings.range)
            return tree.add(near, waypoints) if len(waypoints) else None
        if keep:
            self.pool.add(target[None])
        new = self._far(k, near, target)
        if new is None and not self.pool.reachable(k):
            self.pool.draw(self.pool.batch)
        return new

    def _far(self, k: int, near: int, target: np.ndarray, than: float = np.inf) -> int | None:
        """Extend tree ``k`` toward a ``target`` out of range: to the first valid of the
        ``candidates`` pooled samples within range of it that are closest to ``target`` (and closer
        than ``than``; the tried ones leave the pool). When no pooled sample at all lies within
        range of the tree (samples too sparse for stepping stones), a walk from node ``near`` if
        the local planner walks. The new node or None."""
        tree = self.trees[k]
        slots = self.pool.closest(k, target, self.settings.candidates, than)
        if not len(slots):
            if self.pool.reachable(k):
                return None
            self.out_of_reach += 1
            if not self.local.walks:
                return None
            waypoints, _ = self.local.walk(tree.q[near], target, self.settings.range)
            return tree.add(near, waypoints) if len(waypoints) else None
        stones = self.pool.q[slots]
        nodes = tree.nearest_many(stones)
        i = self.local.first_valid(tree.q[nodes], stones)
        self.pool.free[slots if i < 0 else slots[:i + 1]] = False
        return None if i < 0 else tree.add(nodes[i], stones[i:i + 1])

    def _draw(self) -> np.ndarray:
        """One valid configuration from the sampler."""
        self.samples += 1
        try:
            return self.sampler.sample()
        except ManifoldgenError as exc:
            raise SamplerFailed(str(exc)) from exc

    def _draw_many(self, count: int) -> np.ndarray:
        """(count, n) valid configurations from the sampler."""
        self.samples += count
        try:
            return self.sampler.sample_many(count)
        except ManifoldgenError as exc:
            raise SamplerFailed(str(exc)) from exc

    def _accept(self, path: np.ndarray) -> PathReport:
        """The final dense validation of a candidate path (counts rejections)."""
        report = self.space.validate_path(path)
        self.rejected += not report.valid
        return report

    def _reach_goal(self, tree: Tree, node: int, goal: np.ndarray) -> np.ndarray | None:
        """Join ``node`` to the goal when it is within ``range``, or, with a local planner that
        walks, when it is the closest node to the goal yet (a single tree seldom comes within range
        of a goal that few samples lie near); the accepted path or None."""
        gap = float(np.linalg.norm(goal - tree.q[node]))
        closest = gap < self._goal_gap
        self._goal_gap = min(gap, self._goal_gap)
        if gap > self.settings.range and not (closest and self.local.walks):
            return None
        waypoints = self.local.connect(tree.q[node], goal)
        if waypoints is None:
            return None
        branch = tree.branch(tree.add(node, waypoints))
        return self._finish(tree.q[branch], [(tree, k) for k in branch[1:]])

    def _goal_target(self, goal: np.ndarray, radius: float) -> np.ndarray:
        """A target near the goal for a single tree's goal bias: with stepping stones and a local
        planner that walks, the end of a walk on the manifold from the goal toward a sample, at most
        ``radius`` long (and its last step), whose states all join the pool (a sampler seldom puts
        samples near a given goal, and a tree steps only through samples); else the goal itself."""
        if self.pool is None or not self.local.walks:
            return goal
        waypoints, _ = self.local.walk(goal, self._draw(), radius)
        if not len(waypoints):
            return goal
        self.pool.add(waypoints)
        return waypoints[-1]

    def _toward_goal(self, goal: np.ndarray, radius: float, deadline: float) -> np.ndarray | None:
        """A single tree's goal-biased step: grow toward a target within ``radius`` of the goal (see
        :meth:`_goal_target`) for as long as it makes progress: through the pooled samples that bring
        it closer, as RRT-Connect's connect, else with the local planner (a walk on the manifold
        under ``auto``), trying the goal from every new node; the accepted path or None."""
        tree, target = self.trees[0], self._goal_target(goal, radius)
        while time.perf_counter() < deadline:
            node = tree.nearest(target)
            gap = float(np.linalg.norm(target - tree.q[node]))
            reached = False
            new = None
            if self.pool is not None and gap > self.settings.range:
                new = self._far(0, node, target, than=gap)
            if new is None:  # in range, or no pooled sample brings the tree closer: the local planner
                waypoints, reached = self.local.steer(tree.q[node], target, self.settings.range)
                new = tree.add(node, waypoints) if len(waypoints) else None
            if new is None:
                return None
            path = self._reach_goal(tree, new, goal)
            if path is not None or reached:
                return path
        return None

    def _finish(self, waypoints: np.ndarray, edges: list[tuple[Tree, int]]) -> np.ndarray | None:
        """Dense-check a candidate path; segment s of ``waypoints`` is the edge into node
        ``edges[s] = (tree, child)``. A failing edge is cut from its tree (None returned)."""
        report = self._accept(waypoints)
        if report.valid:
            return waypoints
        tree, child = edges[report.segment]
        tree.kill(child)
        return None


class SamplePool:
    """Samples drawn but not yet in a tree: the stepping stones of straight extensions.

    A straight segment toward a far sample leaves the manifold at once, so a tree grown with
    straight segments cannot step "toward" a random sample the way RRT truncates. Instead it
    steps to the pooled sample, among those within ``radius`` of the tree, that lies
    closest to the random sample: steering on the manifold, through samples. The planner
    fills the pool first, and it draws ``batch`` more whenever no sample is within reach of
    a tree; the distance of every pooled sample to each tree is kept up to date with new
    nodes only. Beyond ``capacity`` the oldest samples leave.
    """

    def __init__(self, draw: Callable[[int], np.ndarray], trees: list[Tree], radius: float, batch: int,
                 capacity: int = 16384):
        self._draw, self.trees, self.radius, self.batch = draw, trees, radius, batch
        self.q = np.zeros((capacity, trees[0].q.shape[1]))
        self.free = np.zeros(capacity, dtype=bool)  # holds an unused sample
        self.gap = np.full((capacity, len(trees)), np.inf)  # distance to the closest node of each tree
        self.synced = [len(t) for t in trees]  # nodes of each tree accounted in gap
        self.head = 0

    def draw(self, count: int) -> None:
        """Add ``count`` new samples from the planner's sampler."""
        self.add(self._draw(count))

    def add(self, q: np.ndarray) -> None:
        """Add samples ``q (B, n)``."""
        slots = (self.head + np.arange(len(q))) % len(self.q)
        self.q[slots], self.free[slots] = q, True
        self.gap[slots] = np.stack([_distances(q, t.q[:s]) for t, s in zip(self.trees, self.synced)], axis=1)
        self.head += len(q)

    @property
    def _filled(self) -> int:
        return min(self.head, len(self.q))

    def _refresh(self, k: int) -> None:
        tree = self.trees[k]
        if len(tree) > self.synced[k]:
            free = np.flatnonzero(self.free[:self._filled])
            fresh = _distances(self.q[free], tree.q[self.synced[k]:tree.size])
            self.gap[free, k] = np.minimum(self.gap[free, k], fresh)
            self.synced[k] = len(tree)

    def reachable(self, k: int) -> bool:
        """Some free sample lies within ``radius`` of tree ``k``."""
        self._refresh(k)
        end = self._filled
        return bool(np.any(self.free[:end] & (self.gap[:end, k] <= self.radius)))

    def closest(self, k: int, target: np.ndarray, count: int, than: float = np.inf) -> np.ndarray:
        """Slots of up to ``count`` free samples within ``radius`` of tree ``k``, closest to
        ``target`` first (and closer to it than ``than``)."""
        self._refresh(k)
        end = self._filled
        near = np.flatnonzero(self.free[:end] & (self.gap[:end, k] <= self.radius))
        diff = self.q[near] - target
        gap = np.einsum("ij,ij->i", diff, diff)
        keep = gap < than * than
        near, gap = near[keep], gap[keep]
        order = np.argsort(gap)[:count] if len(gap) > count else np.argsort(gap)
        return near[order]

    def take_near(self, node: np.ndarray, target: np.ndarray) -> np.ndarray | None:
        """Remove and return the sample within ``radius`` of ``node`` closest to ``target``, or None."""
        free = np.flatnonzero(self.free[:self._filled])
        near = free[np.einsum("ij,ij->i", self.q[free] - node, self.q[free] - node) <= self.radius ** 2]
        if not len(near):
            return None
        best = near[int(np.argmin(np.einsum("ij,ij->i", self.q[near] - target, self.q[near] - target)))]
        self.free[best] = False
        return self.q[best].copy()


def _distances(q: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """(B,) distance from each row of ``q (B, n)`` to its closest row of ``nodes (N, n)``
    (rows of ``nodes`` set to inf, removed nodes, are ignored)."""
    nodes = nodes[np.isfinite(nodes[:, 0])]
    if not len(nodes):
        return np.full(len(q), np.inf)
    d2 = np.einsum("ij,ij->i", q, q)[:, None] - 2 * q @ nodes.T + np.einsum("ij,ij->i", nodes, nodes)[None]
    return np.sqrt(np.maximum(d2.min(axis=1), 0.0))
