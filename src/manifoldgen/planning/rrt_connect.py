"""RRT-Connect (Kuffner & LaValle 2000): two trees, extend one toward a sample, connect the other.

Two searches, one planner name: :class:`CoreRRTConnect` runs in the compiled core (:mod:`manifoldgen.native`),
:class:`RRTConnect` here in Python, the reference the core is tested against. Constructing ``RRTConnect`` picks
the core's when it is built and can take the space (``core="auto"``, the default). Two things differ there, for
speed, not in what a path must pass: the core takes the sampler's raw rows and refines and checks each only when
the search first uses it (lazy samples; here every row is refined and checked when drawn), and its
stepping-stone pool tracks only whether a sample is within range of each tree (the same decisions as
:class:`~manifoldgen.planning.base.SamplePool`)."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from manifoldgen import core_extension, native
from manifoldgen.constraints import projection
from manifoldgen.errors import ManifoldgenError, SamplerFailed
from manifoldgen.planning.base import Planner, PlannerSettings, Tree


EDGE_CHECKS = ("coarse", "dense")  # see RRTConnectSettings.edges
MAX_EDGE_STRIDE = 10**6  # planning-resolution states between coarse checks (beyond, a motion is one check anyway)
TARGET_BATCH = 32  # samples the core's search fetches per callback for its targets (the pool draws pool_batch)


@dataclass
class RRTConnectSettings(PlannerSettings):
    """The shared settings (range, resolution, step, partial, pool, candidates) and ``core``: where the
    search runs: ``auto`` (the compiled core when ``manifoldgen_core`` is usable and can take the space, a
    Python constraint compiled (``extras['compiled']``: which) or, where its residual does not trace or
    ``compile`` is off, through callbacks (``extras['compile_fallback']``: why), else Python; the result's
    ``extras['core']`` says which, ``extras['core_fallback']`` why not native), ``python``, or ``native`` (an
    error when the core cannot run it); ``spheres`` (on by default): the core's collision checks use
    conservative sphere models of the robot as their broad phase, with the same verdicts
    (:mod:`manifoldgen.spheres`: shipped for the package's robots, fitted once and cached for others; a geometry
    without them is checked exactly, ``extras['sphere_fallback']`` says which and why); ``reach``: a pooled
    sample is a stepping stone of a tree when it lies within ``min(reach, range)`` of one of its nodes (shorter
    straight motions to stones: in the maze fewer of them collide; measured in docs/benchmarks.md, "Fairness");
    ``edges``: how the core's search checks a motion for
    collision: ``coarse:K`` checks its planning-resolution states every K-th (and at the node it ends at) while
    the trees grow, the others only when the edge lies on a candidate path (a colliding one is cut from its tree),
    so every returned path is still checked at every planning-resolution state and then densely (``coarse:1``:
    every state at once); ``dense:K`` keeps a motion only when it passes the final path check (the space's dense
    check, ``ValidationSettings.resolution``) as it is made, after a pre-check of its every K-th
    planning-resolution state (every test), so a candidate path is never rejected and needs no check of its own
    (it pays where the trees are about the path and a path check of a motion costs little more than its planning
    check: talos reach, docs/benchmarks.md "Dense edges"). The Python search checks every state at once whatever
    this setting (it is the core's test oracle at ``coarse:1``). ``compile``: a Python constraint's parts run
    in the core as compiled expressions where they trace (off: through callbacks, to compare the two)."""

    core: str = "auto"
    compile: bool = True
    spheres: bool = True
    reach: float = 0.5
    edges: str = "coarse:2"

    def check(self) -> None:
        super().check()
        self.edge_checks()
        if not self.reach > 0:
            raise ManifoldgenError(f"reach must be a positive distance (rad), got {self.reach}; e.g. reach=0.5")
        if self.core not in core_extension.CORES:
            raise ManifoldgenError(f"unknown core '{self.core}'; known: {', '.join(core_extension.CORES)}")

    def edge_checks(self) -> tuple[int, bool]:
        """``edges`` as (stride K >= 1, dense), or a one-line error."""
        kind, _, stride = str(self.edges).partition(":")
        if kind not in EDGE_CHECKS or not stride.isdigit() or not 1 <= int(stride) <= MAX_EDGE_STRIDE:
            raise ManifoldgenError(f"edges must be 'coarse:K' or 'dense:K' with K a whole number from 1 to "
                                   f"{MAX_EDGE_STRIDE:,} (coarse:1: every motion state checked for collision at once), "
                                   f"got {self.edges!r}; e.g. edges='coarse:3'")
        return int(stride), kind == "dense"


class RRTConnect(Planner):
    """Bidirectional RRT, the paper's main planner: the trees take turns to extend toward a
    sample, and after each extension the other tree greedily connects toward the new node.

    This class is the search in Python, the reference. Constructing it gives a :class:`CoreRRTConnect` instead
    where the compiled core can run the query (``settings.core``: ``auto`` or ``native``, see
    :class:`RRTConnectSettings`); ``extras['core']`` says which searched, ``extras['core_fallback']`` why not
    the core."""

    name = "rrtconnect"
    settings_type = RRTConnectSettings

    def __new__(cls, space, *args, settings: RRTConnectSettings | None = None, **kwargs):
        if cls is RRTConnect and _core_refusal(space, settings) is None:
            cls = CoreRRTConnect
        return super().__new__(cls)

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.core = None
        self.fallback = (_core_refusal(self.space, self.settings) or "") if type(self) is RRTConnect else ""
        self.native_nodes: list[int] = []
        self.cut_edges = self.reattached = self.verified_states = 0

    def _stone_radius(self) -> float:
        return min(getattr(self.settings, "reach", self.settings.range), self.settings.range)

    def _solve(self, start, goal, deadline):
        trees = self.trees = [Tree(start), Tree(goal)]
        self._start_pool(trees, deadline)
        while time.perf_counter() < deadline:
            self.iterations += 1
            side = self.iterations % 2
            new = self._grow(side, self._target())
            if new is None:
                continue
            joint = self._connect(1 - side, trees[side].q[new], deadline)
            if joint is None:
                continue
            ends = [(trees[side], new), (trees[1 - side], joint)]
            path = self._join(*ends[side], *ends[1 - side])
            if path is not None:
                return path
        return None

    def _extras(self) -> dict:
        return {"core": "python", **({"core_fallback": self.fallback} if self.fallback else {})}

    def _target(self) -> np.ndarray:
        """The configuration to grow toward: a sample."""
        return self._draw()

    def _connect(self, k: int, target: np.ndarray, deadline: float) -> int | None:
        """Grow tree ``k`` toward ``target`` until it reaches it (returns that node) or is stuck;
        with the pool, through the pooled samples that bring it closer (see :meth:`_far`)."""
        tree = self.trees[k]
        while time.perf_counter() < deadline:
            node = tree.nearest(target)
            gap = float(np.linalg.norm(target - tree.q[node]))
            if self.pool is not None and gap > self.settings.range:
                if self._far(k, node, target, than=gap) is None:
                    return None
                continue
            waypoints, reached = self.local.steer(tree.q[node], target, self.settings.range)
            if not len(waypoints):
                return None
            node = tree.add(node, waypoints)
            if reached:
                return node
        return None

    def _join(self, a: Tree, i: int, b: Tree, j: int) -> np.ndarray | None:
        """The path root(a) .. node i == node j .. root(b), densely checked."""
        pa, pb = a.branch(i), b.branch(j)
        waypoints = np.concatenate([a.q[pa], b.q[pb[-2::-1]]])
        edges = [(a, k) for k in pa[1:]] + [(b, k) for k in pb[:0:-1]]
        return self._finish(waypoints, edges)


class CoreRRTConnect(RRTConnect):
    """RRT-Connect in the compiled core (``manifoldgen_core.rrt_connect``, :meth:`_solve`): the same search as
    :class:`RRTConnect` on the same validity rule, with the differences the module docstring names (lazy samples,
    the pool's range bookkeeping, ``edges``); the tests hold both to the same verdicts. Made by
    :class:`RRTConnect` when the core takes the space."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.core = native.core_space(self.space, compile=self.settings.compile)
        self.compiled = native.compile_report(self.space)  # Python parts compiled in the core, and why not the others
        self.sphere_fallback: dict[str, str] = {}  # robot geometry -> why it has no spheres (coal checks it)
        if self.settings.spheres and self.space.checker is not None:
            spheres = native.space_spheres(self.space)
            native.set_spheres(self.core, spheres)
            self.sphere_fallback = spheres["fallback"]
        self._core_counts = self.core.counts()  # when the latest query began

    def _direct(self, start, goal):
        return None

    def solve(self, start, goal, time_limit):
        self._core_counts = self.core.counts()  # the query's sphere and sweep tests, callbacks: from here on
        return super().solve(start, goal, time_limit)

    def _query_state(self, q, what):
        valid = native.valid_query_state(self.space, self.core, q)
        return valid if valid is not None else super()._query_state(q, what)  # the space says what is wrong

    def _solve(self, start, goal, deadline):
        """The direct connection, then the search, in the core until ``deadline`` (``time.perf_counter`` seconds).
        The sampler's raw rows (:meth:`~manifoldgen.sampling.Sampler.raw_many`) go to the core, which refines
        (``sampler.lazy_refine`` iterations) and checks each when it first uses it (lazy samples). Books
        iterations, samples, rejections, projections, the sampler's refined and accepted rows and the core's
        operation counts; the path (K, n) that passed the exact dense check, or None."""
        space, sampler, core = self.space, self.sampler, self.core
        before = core.counts()
        try:
            out = core_extension.core_module().rrt_connect(
                core, np.ascontiguousarray(start, float), np.ascontiguousarray(goal, float), _core_draw(sampler),
                max(deadline - time.perf_counter(), 0.0), core_settings(self, int(sampler.lazy_refine)))
        finally:
            native.book(space, before, core.counts())
        self.iterations += out["iterations"]
        self.samples += out["samples"]
        self.rejected += out["rejected_paths"]
        self.out_of_reach += out["out_of_reach"]
        self.local.projections += out["projections"]
        self.native_nodes = list(out["nodes"])
        self.cut_edges = out["cut_edges"]
        self.verified_states = out["verified_states"]
        self.reattached = out["reattached"]
        self.shortcuts, self.relaxed, self.found_length = out["shortcuts"], out["relaxed"], out["found_length"]
        sampler.stats.refined += out["refined"] if sampler.lazy_refine else 0
        sampler.stats.checked += out["refined"]  # raw rows the search made samples (refined, then checked)
        sampler.stats.accepted += out["accepted"]
        return out["path"] if len(out["path"]) else None

    def _shorten(self, path, deadline):
        return path  # the core shortened it (found_length, shortcuts and relaxed booked by _solve)

    def _segment_valid(self, segment):
        before = self.core.counts()
        valid = self.core.validate_path(np.ascontiguousarray(segment, float), certify=True)[0]
        native.book(self.space, before, self.core.counts())
        return bool(valid)

    def _extras(self) -> dict:
        now, then = self.core.counts(), self._core_counts
        callbacks = {k: now[f"callback_{k}"] - then[f"callback_{k}"] for k in ("calls", "rows")}  # into a Python constraint
        return {"core": "native", "nodes": list(self.native_nodes),
                "sphere_checks": now["sphere_checks"] - then["sphere_checks"],
                "sweep_checks": now["sweep_checks"] - then["sweep_checks"],
                "cut_edges": self.cut_edges, "reattached": self.reattached, "verified_states": self.verified_states,
                **({"callbacks": callbacks} if callbacks["calls"] else {}),
                **({"compiled": list(self.compiled["compiled"])} if self.compiled["compiled"] else {}),
                **({"compile_fallback": "; ".join(f"{kind}: {why}" for kind, why in self.compiled["callbacks"].items())}
                   if self.compiled["callbacks"] else {}),
                **({"sphere_fallback": self.sphere_fallback} if self.sphere_fallback else {})}


def core_settings(planner: RRTConnect, refine: int):
    """The core's ``PlannerSettings`` for ``planner``: every field from its settings dataclass, its local planner
    (its projections' precision and iterations) and stone radius, :func:`~manifoldgen.constraints.project`'s
    tolerance, damping and step, and ``refine`` (projection iterations of a raw row when the search first uses
    it). The one place the two languages' settings cross."""
    s = planner.settings
    stride, dense = s.edge_checks()
    pool, pool_batch = planner.pool_rows()
    return core_extension.core_module().PlannerSettings(
        range=s.range, resolution=s.resolution, step=s.step, partial=s.partial, pool=pool, pool_batch=pool_batch,
        candidates=s.candidates, target_batch=TARGET_BATCH, local=planner.local.name, edge_stride=stride,
        dense_edges=dense, refine=refine, reach=planner._stone_radius(), shortcut=s.shortcut,
        precision=planner.local.precision, max_iters=planner.local.max_iters, tol=projection.TOL,
        damping=projection.DAMPING, max_step=projection.MAX_STEP)


def _core_draw(sampler):
    """The core search's callback: ``count`` -> (count, n) raw rows of ``sampler``
    (:meth:`~manifoldgen.sampling.Sampler.raw_many`); a sampler's error ends the search."""
    def draw(count: int) -> np.ndarray:
        try:
            return sampler.raw_many(count)
        except ManifoldgenError as exc:
            raise SamplerFailed(str(exc)) from exc
    return draw


def _core_refusal(space, settings) -> str | None:
    """Why the compiled core does not run this RRT-Connect query: None when it does, '' when ``core='python'``
    asks for Python, else the reason (the core not built, a space it cannot take); with ``core='native'`` the
    reason is a one-line error."""
    wanted = getattr(settings, "core", "python") if settings is not None else RRTConnectSettings.core
    if wanted == "python":
        return ""
    problem = core_extension.core_problem()
    reason = problem or core_extension.unsupported(space)
    if reason and wanted == "native":
        raise ManifoldgenError(problem or f"{reason}; use core='python' or 'auto'")
    return reason or None
