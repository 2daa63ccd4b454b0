"""Collecting datasets of constraint-satisfying configurations (:class:`~manifoldgen.dataset.Dataset`).

A collected file's ``meta`` holds ``format_version``, ``robot``, ``joints``, ``locked``, ``constraint``, ``seed``
(see :meth:`manifoldgen.tasks.Task.meta`). Collection projects uniform seeds batch by batch (in the compiled
core where it takes the task: :func:`manifoldgen.native.fast_space`);
batch ``b`` of condition ``c`` draws from ``default_rng([seed, c, b])``, and every
finished batch is saved under ``<out>.partial/``, so an interrupted run resumes where it
stopped and produces the same file as an uninterrupted one. Given query anchors (the start and
goal configurations of the task's scenes, :mod:`manifoldgen.coverage`), half of every batch's seeds are drawn
around them, so the rows cover the IK branches the task will be queried on; the meta then records the anchors.
Every dataset's meta holds ``coverage``: the modes found at each condition and each anchor's distance to the
nearest row. ``<out>.partial/meta.json`` records
everything that defines the output (task spec with the robot's identity, condition values, rows
per condition, seed, batch settings); a rerun that differs in any of them is refused, naming the
difference, instead of mixing rows. A run that fails with an error removes its partial folder.

With a :class:`~manifoldgen.cluster.Cluster`, every batch (the shard: one condition, one seed block) is a task on
the cluster (:func:`draw_batch` on a worker, the task rebuilt there from its spec); the driver submits batches
ahead of the one it needs, saves each as it arrives and takes them in order, so the file is byte for byte the
one a local run writes, whatever the number of workers or the order they finish in.
"""

from __future__ import annotations

import functools
import json
import re
import shutil
from pathlib import Path

import numpy as np

from manifoldgen.cluster import Cluster, Pool, connect
from manifoldgen.coverage import ANCHOR_SPREAD, Anchors, anchor_seeds, gaps, missed, modes, rows_at, spacing
from manifoldgen.dataset import FORMAT_VERSION, MAX_NEAR_HOME, Dataset
from manifoldgen.errors import ManifoldgenError, differences, listed, short
from manifoldgen.io import atomic_write_text, check_output_path, load_npz, locks_output, save_npz
from manifoldgen.native import fast_space
from manifoldgen.progress import progress_bar
from manifoldgen.runtime import check_seed
from manifoldgen.scene import task_checker
from manifoldgen.space import ConstrainedSpace
from manifoldgen.tasks import Task, code_types, task_from_spec

MAX_ROWS = 10_000_000  # rows one dataset may hold (they are kept in memory: 80 bytes per joint and 1000 rows)
DEFAULT_ROWS = 10_000  # rows a collection makes by default, shared by its condition values ...
MIN_PER_CONDITION = 200  # ... but at least this many at each
DIAGNOSED = 256  # projected seeds that say why a condition gave too few rows


def default_rows(conditions: int) -> int:
    """Rows per condition value by default for ``conditions`` values (see :data:`DEFAULT_ROWS`)."""
    return max(MIN_PER_CONDITION, -(-DEFAULT_ROWS // max(1, conditions)))


@locks_output("out")  # one writer per output: a second collect into the same file is refused
def collect(task: Task, per_condition: int, seed: int, out: str | Path | None = None, *,
            conditions: np.ndarray | None = None, batch: int = 2048, max_batches: int = 1000,
            give_up: int = 20, progress: bool = True, near_home: float = 0.0,
            anchors: Anchors | None = None, cluster: Cluster | None = None) -> Dataset:
    """Collect ``per_condition`` valid rows at each condition value (default: the task's).

    The seeds projected onto the manifold are uniform in the joint limits; with ``anchors`` (see
    :func:`manifoldgen.scene.task_anchors`; what ``manifoldgen collect`` passes for a task with scenes)
    half of them are normal around the anchors instead; with ``near_home > 0`` all are normal around the task's
    home with that standard deviation (rad, at most :data:`~manifoldgen.dataset.MAX_NEAR_HOME`, clipped to the
    limits): rows on the home's IK branch (for a task whose manifold has many branches, such as baxter's dual-arm tray,
    where a unimodal model trained on uniform seeds averages the branches into a pose far from every
    query solved near the home).

    A condition that yields no valid row in its first ``give_up`` batches is an error.
    With ``out``, batches are saved as they finish and the dataset is written atomically
    at the end; rerunning the same command after an interruption resumes. With ``cluster``, the batches are
    drawn on it (the same file; a run on a cluster and one without resume each other).
    """
    if per_condition <= 0:
        raise ManifoldgenError(f"--per-condition must be a positive number of rows, got {per_condition}")
    seed = check_seed(seed)
    if not 0 <= near_home <= MAX_NEAR_HOME:
        raise ManifoldgenError(f"near_home must be a standard deviation from 0 to {MAX_NEAR_HOME:g} rad (0: uniform "
                               f"seeds; wider ones pile the rows at the joint limits), got {near_home}")
    if min(batch, max_batches, give_up) <= 0:
        raise ManifoldgenError(f"batch, max_batches and give_up must be positive, got {batch}, {max_batches}, "
                               f"{give_up}")
    values = _condition_values(task, conditions)
    if per_condition * len(values) > MAX_ROWS:
        raise ManifoldgenError(f"{per_condition} rows per condition at {len(values)} condition value(s) make more "
                               f"than {MAX_ROWS:,} rows; collect several smaller datasets")
    if cluster is not None and code_types(task.spec()):
        raise ManifoldgenError("--cluster rebuilds the task on every node, which never imports a user's module:Class "
                               "constraint; collect this task without --cluster")
    if anchors is not None and not isinstance(anchors, Anchors):
        raise ManifoldgenError(f"anchors must be query anchors (manifoldgen.scene.task_anchors) or None, got "
                               f"{anchors!r:.60}")
    anchors = anchors if anchors is not None and len(anchors) else None
    if near_home and anchors is not None:
        raise ManifoldgenError("--near-home and query anchors are two seedings; give one (--no-anchors with "
                               "--near-home)")
    method = ("uniform seeds" if not (near_home or anchors) else
              f"seeds normal around the task home (sd {near_home:g} rad)" if near_home else
              f"half uniform seeds, half normal around the query anchors (sd {ANCHOR_SPREAD:g} rad)")
    meta = {"format_version": FORMAT_VERSION, **task.meta(), "seed": seed, "per_condition": per_condition,
            "method": f"{method} + damped least-squares projection",
            **({"near_home": float(near_home)} if near_home else {}),
            **({"anchors": anchors.to_meta(), "scenes": anchors.scenes} if anchors else {})}
    partial, owned = None, False  # owned: this run may remove the partial folder when it fails
    if out is not None:
        out = check_output_path(out, kind="dataset")
        partial = out.with_name(out.name + ".partial")
        if partial.exists() and not partial.is_dir():
            raise ManifoldgenError(f"{partial} is a file where collect keeps the batches of an unfinished run (a "
                                   "folder); move or delete it, or choose another output (-o)")
        owned = not partial.exists()
        if owned and out.exists():
            _check_finished(out, meta, values)
    try:
        if partial is not None:
            _prepare_partial(partial, {**meta, "conditions": values.tolist(), "batch": batch,
                                       "max_batches": max_batches, "give_up": give_up})
            owned = True
        draw = _Draw(task, seed, batch, near_home, anchors, partial)
        if cluster is None:
            dataset = _collect(task, values, per_condition, max_batches, give_up, progress, meta, draw)
        else:
            with connect(cluster) as pool:
                dataset = _collect(task, values, per_condition, max_batches, give_up, progress, meta,
                                   _Shards(draw, pool, values, per_condition, max_batches))
        dataset.meta["coverage"] = coverage(dataset, anchors, seed)
        if out is not None:
            dataset.save(out)
    except Exception:  # a failed run leaves nothing behind (an interrupt or a kill keeps the batches to resume)
        if owned:
            shutil.rmtree(partial, ignore_errors=True)
        raise
    if partial is not None:
        shutil.rmtree(partial, ignore_errors=True)
    return dataset


def draw_batch(task: Task, space: ConstrainedSpace, c: int, b: int, seed: int, batch: int, near_home: float = 0.0,
               anchors: Anchors | None = None) -> np.ndarray:
    """The valid rows (R, n) of batch ``b`` at condition value ``c`` (``space``'s): ``batch`` seeds drawn from
    ``default_rng([seed, c, b])``, projected, kept where valid."""
    robot = task.robot
    rng = np.random.default_rng([seed, c, b])
    seeds = (np.clip(task.home + rng.normal(0.0, near_home, (batch, robot.n)), robot.lower, robot.upper)
             if near_home else robot.sample_uniform(batch, rng))
    if anchors is not None:
        seeds[1::2] = anchor_seeds(anchors, batch // 2, rng, robot)  # interleaved: any prefix is half
    fast = fast_space(space)  # the compiled core's projection and validity where it takes the task
    res = fast.project(seeds)
    return res.q[fast.valid(res.q)]


class _Draw:
    """Batches drawn here, each saved under ``partial`` (when given) as it is drawn."""

    def __init__(self, task: Task, seed: int, batch: int, near_home: float, anchors: Anchors | None,
                 partial: Path | None):
        self.task, self.seed, self.batch, self.near_home, self.anchors = task, seed, batch, near_home, anchors
        self.partial = partial

    def save(self, c: int, b: int, rows: np.ndarray) -> None:
        if self.partial is not None:
            save_npz(self.partial / f"c{c}-b{b}.npz", {}, q=rows)

    def __call__(self, space: ConstrainedSpace, c: int, b: int, got: int) -> np.ndarray:
        """Batch ``b`` of condition ``c`` (``got``: the rows its earlier batches gave)."""
        rows = draw_batch(self.task, space, c, b, self.seed, self.batch, self.near_home, self.anchors)
        self.save(c, b, rows)
        return rows


@functools.lru_cache(maxsize=4)
def _worker_task(spec: str) -> tuple[Task, object]:
    """The task (and its collision checker) a worker rebuilds from its spec, once per worker process."""
    task = task_from_spec(json.loads(spec))
    return task, task_checker(task)


@functools.lru_cache(maxsize=64)
def _worker_space(spec: str, y: tuple[float, ...]) -> ConstrainedSpace:
    """The space at condition ``y`` on a worker, built once per worker process like the one space per condition of
    a local run (so the compiled core's copy of it is built once too, not for every batch)."""
    task, checker = _worker_task(spec)
    return ConstrainedSpace(task.constraint, np.array(y), checker)


def _remote_batch(spec: str, y: np.ndarray, c: int, b: int, seed: int, batch: int, near_home: float,
                  anchors: Anchors | None) -> np.ndarray:
    """:func:`draw_batch` on a cluster's worker."""
    task, _ = _worker_task(spec)
    space = _worker_space(spec, tuple(np.asarray(y, dtype=float).tolist()))
    return draw_batch(task, space, c, b, seed, batch, near_home, anchors)


class _Shards:
    """Batches drawn on a cluster: the one asked for, and ahead of it those that the rows seen so far say will be
    needed (a surplus batch is drawn for nothing; the file never depends on which). Each is saved as it arrives."""

    def __init__(self, draw: _Draw, pool: Pool, values: np.ndarray, per_condition: int, max_batches: int):
        self.draw, self.pool, self.values = draw, pool, values
        self.partial, self.batch = draw.partial, draw.batch
        self.per_condition, self.max_batches = per_condition, max_batches
        self.spec = pool.put(json.dumps(draw.task.spec(), sort_keys=True))
        self.arrived: dict[tuple[int, int], np.ndarray] = {}
        self.counts: dict[int, list[int]] = {}  # condition -> rows of each batch seen

    def _rate(self, c: int) -> float:
        """Expected rows of a batch at condition ``c`` (optimistic before any has arrived)."""
        seen = self.counts.get(c) or [n for counts in self.counts.values() for n in counts]
        return sum(seen) / len(seen) if seen else float(self.per_condition)

    def _submit(self, c: int, b: int) -> None:
        d = self.draw
        self.pool.submit((c, b), _remote_batch, self.spec, self.values[c], c, b, d.seed, d.batch, d.near_home,
                         d.anchors)

    def _ahead(self, c: int, b: int, got: int) -> None:
        """Fill the free slots with the first batches, from (c, b) on, not yet expected to complete a condition."""
        running = set(self.pool.pending.values())
        for cc in range(c, len(self.values)):
            expected, rate = (got, self._rate(cc)) if cc == c else (0, self._rate(cc))
            for bb in range(b if cc == c else 0, self.max_batches):
                if expected >= self.per_condition or not self.pool.free():
                    break
                if (cc, bb) in self.arrived:
                    expected += len(self.arrived[cc, bb])
                    continue
                if (cc, bb) not in running and not (self.partial is not None and
                                                    (self.partial / f"c{cc}-b{bb}.npz").exists()):
                    self._submit(cc, bb)
                expected += rate
            if not self.pool.free():
                return

    def __call__(self, space: ConstrainedSpace, c: int, b: int, got: int) -> np.ndarray:
        """Batch ``b`` of condition ``c`` (``got``: the rows its earlier batches gave)."""
        if (c, b) not in self.arrived and (c, b) not in self.pool.pending.values():
            self._submit(c, b)  # first, or a saved batch that proved damaged
        self._ahead(c, b, got)
        while (c, b) not in self.arrived:
            for (cc, bb), rows, _ in self.pool.wait():
                self.draw.save(cc, bb, rows)
                self.counts.setdefault(cc, []).append(len(rows))
                if cc >= c:  # a surplus batch of a finished condition is dropped
                    self.arrived[cc, bb] = rows
            self._ahead(c, b, got)  # the freed slots, at once
        return self.arrived.pop((c, b))


def _collect(task: Task, values: np.ndarray, per_condition: int, max_batches: int, give_up: int, progress: bool,
             meta: dict, draw) -> Dataset:
    """Take batches in order (saved ones first, the others from ``draw``) until every condition has its rows."""
    checker = task_checker(task)
    qs, ys = [], []
    with progress_bar("collecting", total=per_condition * len(values), enabled=progress) as bar:
        for c, y in enumerate(values):
            space = ConstrainedSpace(task.constraint, y, checker)
            got = []
            for b in range(max_batches):
                if sum(len(g) for g in got) >= per_condition:
                    break
                rows = _load_batch(draw.partial, c, b, task.robot.n)
                if rows is not None and not fast_space(space).valid(rows).all():
                    rows = None  # a saved batch that is not valid here (damaged, or from elsewhere) is recomputed
                if rows is None:
                    rows = draw(space, c, b, sum(len(g) for g in got))
                got.append(rows)
                if b + 1 >= give_up and not sum(len(g) for g in got):
                    break
                bar.advance(min(len(rows), per_condition - sum(len(g) for g in got[:-1])))
            q = np.concatenate(got)[:per_condition]
            if len(q) < per_condition:
                raise ManifoldgenError(f"only {len(q)} valid rows at condition {y.tolist()} after "
                                       f"{len(got)} batches of {draw.batch}; {_why_none(task, space, y)}")
            qs.append(q)
            ys.append(np.broadcast_to(y, (per_condition, len(y))))
    return Dataset(np.concatenate(qs), np.concatenate(ys).copy(), meta)


def _why_none(task: Task, space: ConstrainedSpace, y: np.ndarray) -> str:
    """Why few rows are valid at ``y``: outside the task's condition range, or (inside it) what rejects
    :data:`DIAGNOSED` projected uniform seeds (the tolerance, the joint limits, the inequalities, collisions)."""
    condition = task.condition
    if np.any((y < condition.low) | (y > condition.high)):
        return f"the condition is probably unreachable: choose values inside {condition.describe()}"
    robot, constraint = task.robot, task.constraint
    q = space.project(robot.sample_uniform(DIAGNOSED, np.random.default_rng(0))).q
    limits = ~robot.within_limits(q)
    tolerance = ~limits & (constraint.violation(q, y) > 1.0)
    inequality = ~limits & ~tolerance & np.any(constraint.inequality(q, y) > 0, axis=1)
    rest = ~(limits | tolerance | inequality)
    collision = int(space.checker.in_collision(q[rest]).sum()) if space.checker is not None and rest.any() else 0
    return (f"{y.tolist()} is inside {condition.describe()}, but of {DIAGNOSED} projected seeds {tolerance.sum()} "
            f"missed the tolerance (smallest {constraint.tolerance.min():g}), {limits.sum()} left the limits, "
            f"{inequality.sum()} broke an inequality, {collision} collided: check the task's tolerances")


def coverage(dataset: Dataset, anchors: Anchors | None, seed: int = 0) -> dict:
    """What the rows cover, JSON-ready: ``modes`` (per condition value, the shares of its rows in each mode,
    largest first: IK branches, see :func:`manifoldgen.coverage.modes`) and, with anchors, ``anchors``: each
    one's label, its distance ``gap`` (rad) to the nearest row at the condition nearest its own, the rows'
    ``spacing`` there (median distance to the nearest other row) and ``missed`` (see
    :func:`manifoldgen.coverage.missed`)."""
    values = np.unique(dataset.y, axis=0)
    found = {json.dumps(v.tolist()): [round(m["share"], 4) for m in modes(dataset.q[np.all(dataset.y == v, axis=1)],
                                                                          seed)] for v in values}
    report: dict = {"modes": found}
    if anchors is not None:
        report["anchors"] = []
        for label, q, y in zip(anchors.labels, anchors.q, anchors.y):
            rows = rows_at(dataset.q, dataset.y, y)
            gap, space = float(gaps(rows, q)[0]), spacing(rows, seed)
            report["anchors"].append({"label": label, "gap": round(gap, 4), "spacing": round(space, 4),
                                      "missed": bool(missed(gap, space))})
    return report


def _prepare_partial(partial: Path, settings: dict) -> None:
    """Resume a previous run's batches only if it ran with the same ``settings``; refuse otherwise."""
    stamp = partial / "meta.json"
    settings = json.loads(json.dumps(settings))
    others = sorted(f.name for f in partial.iterdir() if not _collects_own(f.name)) if partial.exists() else []
    if others:
        raise ManifoldgenError(f"{partial} holds files collect did not write ({listed(others[:3], ', ')}); it keeps "
                               "the batches of an unfinished run there: move or delete that folder")
    if stamp.exists() and not any(partial.glob("c*-b*.npz")):  # a run stopped before its first batch, or not ours
        try:
            ours = set(json.loads(stamp.read_text())) == set(settings)
        except (OSError, ValueError, TypeError):
            ours = False
        if not ours:
            raise ManifoldgenError(f"{stamp} is not the record of an unfinished collection; move or delete "
                                   f"{partial}")
    if partial.exists() and any(partial.glob("c*-b*.npz")):
        try:
            old = json.loads(stamp.read_text())
        except (OSError, ValueError):
            raise ManifoldgenError(f"{partial} holds batches of an interrupted collection but no readable "
                                   f"meta.json; delete {partial} to start over") from None
        changed = differences(old, settings)
        if changed:
            raise ManifoldgenError(f"{partial} holds an interrupted collection made with other settings "
                                   f"({changed}); rerun the same command to resume it, or delete "
                                   f"{partial} to start over")
    partial.mkdir(parents=True, exist_ok=True)
    atomic_write_text(stamp, json.dumps(settings))


def _collects_own(name: str) -> bool:
    """Whether a file named ``name`` in a partial folder is one collect writes: its meta.json, a batch, or a
    temporary file of an interrupted atomic write."""
    return re.fullmatch(r"meta\.json|c\d+-b\d+\.npz|\.(meta\.json|c\d+-b\d+\.npz)\.\d+-.+\.tmp", name) is not None


def _condition_values(task: Task, conditions) -> np.ndarray:
    """The condition values to collect at, (V, k): ``conditions`` (default: the task's), each given once."""
    k = task.condition.k
    if conditions is None or not k:
        return task.condition.grid
    values = None
    try:
        odd = next((v for v in np.asarray(conditions, dtype=object).ravel()
                    if isinstance(v, (bool, np.bool_, str, bytes))), None)
        values = np.asarray(conditions, float) if odd is None else None
    except (TypeError, ValueError):
        odd = conditions
    if values is None or odd is not None:
        raise ManifoldgenError(f"conditions must be condition values (V, {k}) as numbers, got {short(odd)}")
    if values.ndim == 1:  # one value per row (k = 1), or a single row
        values = values[:, None] if k == 1 else values[None]
    if values.ndim != 2 or values.shape[1] != k or not len(values):
        names = ", ".join(task.condition.names)
        raise ManifoldgenError(f"conditions must be condition values of shape (V, {k}) ({names} per row), got shape "
                               f"{values.shape}")
    if not np.isfinite(values).all():
        raise ManifoldgenError(f"condition values must be finite numbers, got {values[~np.isfinite(values)][0]}")
    seen: set[tuple] = set()
    twice = next((row for row in map(tuple, values.tolist()) if row in seen or seen.add(row)), None)
    if twice is not None:
        raise ManifoldgenError(f"condition value {list(twice)} is given twice; give each value once (rows per "
                               "value: --per-condition)")
    return values


def _check_finished(out: Path, meta: dict, values: np.ndarray) -> None:
    """Refuse to replace a finished dataset ``out`` unless this run, made with ``meta`` at ``values``, is the one
    that wrote it (it then writes the same file again)."""
    try:
        old, arrays = load_npz(out, ("y",))
        made = np.unique(arrays["y"], axis=0, return_index=True)
        old = {**old, "conditions": arrays["y"][np.sort(made[1])].tolist()}
    except ManifoldgenError:
        raise ManifoldgenError(f"{out} exists and is not a dataset; choose another output (-o), or delete it") \
            from None
    old.pop("coverage", None)
    changed = differences(old, {**meta, "conditions": values.tolist()})
    if changed:
        raise ManifoldgenError(f"{out} holds a dataset made with other settings ({changed}); choose another "
                               "output (-o), or delete it to collect anew")


def _load_batch(partial: Path | None, c: int, b: int, n: int) -> np.ndarray | None:
    """A saved batch's rows (R, n), or None when it is missing or damaged (then it is recomputed)."""
    if partial is None or not (partial / f"c{c}-b{b}.npz").exists():
        return None
    try:
        q = load_npz(partial / f"c{c}-b{b}.npz", ("q",))[1]["q"]
    except ManifoldgenError:
        return None
    ok = q.dtype == np.float64 and q.ndim == 2 and q.shape[1] == n and np.isfinite(q).all()
    return q if ok else None
