"""Samplers: what planners draw configurations from.

Every sampler serves one :class:`~manifoldgen.space.ConstrainedSpace` (a constraint at a fixed
condition ``y``, with or without a collision checker) and returns, from ``sample()``, one
configuration ``(n,)`` valid in it. Candidates are produced in batches and kept in a buffer, as
in the paper's Algorithm 1; ``stats`` counts what it cost.

A candidate is a raw row (a model decode, a uniform seed: :meth:`Sampler.raw`) refined by
``lazy_refine`` projection iterations and checked. :meth:`Sampler.sample_many` does both before it
returns a row; :meth:`Sampler.raw_many` returns raw rows for a search that refines and checks a row
only when it first uses it (the compiled core's RRT-Connect: most pooled rows are never used).

A model sampler is never left worse than projection: at the start of a query (:meth:`ModelSampler.begin_query`)
it measures how far its samples lie from the start and the goal, and when the model misses either (an IK
branch it never learned) it mixes projected uniform rows into every batch at once; otherwise it starts mixing
them only when a query has drawn :data:`MIX_AFTER` rows without solving, up to :data:`MIX_MAX` of each batch.
A model whose ``mix`` is 1 (``train`` raced it on the task's scenes and plain projection planned fastest, see
:mod:`manifoldgen.selection`) stands for the projection sampler: :func:`model_sampler`.
"""

from __future__ import annotations

import inspect
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from manifoldgen.constraints import Constraint, project
from manifoldgen.errors import ManifoldgenError
from manifoldgen.native import fast_space
from manifoldgen.provenance import check_model_for
from manifoldgen.runtime import REFINE, check_seed
from manifoldgen.space import ConstrainedSpace

PROJECT_ITERS = inspect.signature(project).parameters["max_iters"].default  # the projection sampler's iterations
FIRST_ROWS = 64  # a model sampler's first batch; each next one doubles, up to its batch size
REFERENCE_ROW_COST = 17_792  # multiply-adds of a row of the shipped panda CVAE (4-128-128-7): row counts (a model
# sampler's batch, a planner's pool) hold for a row this cheap, and shrink in proportion for a dearer one (cost_scale)
CHECK_ROWS = 256  # model rows a sampler draws when made, to measure each query's gaps at its start and goal
MIX_MAX = 0.5  # a query mixes in at most this share of projected uniform rows while the model covers its ends
MIX_MISSED = 0.9  # the share of projected uniform rows in a query whose start or goal the model misses
MIX_AFTER = 20_000  # raw rows a query draws before a model that covers its ends starts mixing (full after twice)
MAX_SAMPLES = 1_000_000  # rows one sample_many or raw_many call returns (a planner's pool asks for at most this)
INFORMED_PROBE, INFORMED_SHARE = 512, 0.01  # a restricted sampler gives up when, of the first 512 or more rows it
# drew, under 1 % lay inside the informed set (a search would starve on them: talos's reach, 0.02 %)


@dataclass
class SamplerStats:
    """Counts since construction: candidates made (``generated``: decoded, for a model), projected (``refined``),
    checked as samples (``checked``: limits and constraint; most of a search's pooled rows never are) and accepted;
    batches drawn; ``mixed``: candidates that were projected uniform rows mixed into a model's (see
    :class:`ModelSampler`)."""

    generated: int = 0
    refined: int = 0
    checked: int = 0
    accepted: int = 0
    batches: int = 0
    mixed: int = 0

    def to_dict(self) -> dict:
        return dict(vars(self))  # the counts are plain ints: no deep copy (asdict's) needed


class Sampler(ABC):
    """Algorithm 1: pop buffered candidates, return the first valid one, refill when empty."""

    def __init__(self, space: ConstrainedSpace, *, batch: int = 256, seed: int | np.random.Generator = 0,
                 max_batches: int = 10_000):
        self.space = space
        self.batch, self.max_batches = batch, max_batches
        self.rng = np.random.default_rng(seed)
        self.stats = SamplerStats()
        self._buffer = self._raw = np.zeros((0, space.n))
        self.informed: tuple[np.ndarray, np.ndarray, float] | None = None  # (start, goal, length): see restrict

    lazy_refine: int = 0  # projection iterations (constraints.project, default options) that refine a raw row
    row_cost: int | None = None  # multiply-adds to make a raw row (a model's decode); None: next to nothing
    scene: tuple[str, str] | None = None  # (name, fingerprint) of the scene whose obstacles its space holds, where
    # known (manifoldgen.api.sampler sets it, so that a plan of another scene's query refuses the sampler)

    @abstractmethod
    def candidates(self, count: int) -> np.ndarray:
        """(count, n) new candidate configurations (refined, not yet checked)."""

    def raw(self, count: int) -> np.ndarray:
        """(count, n) new raw candidates: :meth:`candidates` before ``lazy_refine`` projection iterations."""
        return self.candidates(count)

    def _batch_rows(self) -> int:
        """Rows in the next batch: ``batch``."""
        return self.batch

    def restrict(self, start: np.ndarray, goal: np.ndarray, length: float) -> None:
        """From now on keep only rows ``x`` with ``|x - start| + |x - goal| < length``: the states a path from
        ``start`` to ``goal`` shorter than ``length`` can visit (the informed set of Gammell et al., 2014); the
        buffered rows are dropped. :meth:`unrestrict` ends it."""
        self.informed = (np.asarray(start, float), np.asarray(goal, float), float(length))
        self._buffer = self._raw = np.zeros((0, self.space.n))
        self._informed_counts = [0, 0]  # rows drawn, rows inside

    def unrestrict(self) -> None:
        """Draw from the whole manifold again (see :meth:`restrict`)."""
        self.informed = None
        self._buffer = self._raw = np.zeros((0, self.space.n))

    def _informed_rows(self, q: np.ndarray) -> np.ndarray:
        """The rows of ``q (B, n)`` inside the informed set (all of them when unrestricted); an error once
        :data:`INFORMED_PROBE` rows or more were drawn and under :data:`INFORMED_SHARE` of them lay inside."""
        if self.informed is None:
            return q
        start, goal, length = self.informed
        inside = q[np.linalg.norm(q - start, axis=1) + np.linalg.norm(q - goal, axis=1) < length]
        counts = self._informed_counts
        counts[0], counts[1] = counts[0] + len(q), counts[1] + len(inside)
        if counts[0] >= INFORMED_PROBE and counts[1] < INFORMED_SHARE * counts[0]:
            raise ManifoldgenError(f"{type(self).__name__}: {counts[1]} of its {counts[0]} rows lay inside the "
                                   f"informed set (a path shorter than {length:.3g} rad): too few to search on")
        return inside

    def _refill(self) -> None:
        """A new batch of checked candidates into the buffer :meth:`sample_many` takes from."""
        q = self.candidates(self._batch_rows())
        self.stats.generated += len(q)
        self.stats.batches += 1
        q = self._informed_rows(q)
        self.stats.checked += len(q)
        self._buffer = q[self.space.valid(q)]

    def _refill_raw(self) -> None:
        """A new batch of raw candidates into the buffer :meth:`raw_many` takes from."""
        raw = self.raw(self._batch_rows())
        self.stats.generated += len(raw)
        self.stats.batches += 1
        self._raw = self._informed_rows(raw)

    def sample(self) -> np.ndarray:
        """One valid configuration (n,)."""
        return self.sample_many(1)[0]

    def sample_many(self, count: int) -> np.ndarray:
        """(count, n) valid configurations (``count`` at most :data:`MAX_SAMPLES`): the buffer taken in order, in
        slices, refilled a batch at a time; an error after ``max_batches`` refills in a row found none."""
        rows = self._take(count, "_buffer", self._refill)
        self.stats.accepted += len(rows)
        return rows

    def raw_many(self, count: int) -> np.ndarray:
        """(count, n) raw candidates (see :meth:`raw`), unrefined and unchecked: the caller refines each
        with ``lazy_refine`` projection iterations, checks it, and books ``stats.refined`` and
        ``stats.accepted``. At most :data:`MAX_SAMPLES`, made ``batch`` at a time as :meth:`sample_many`; an
        error after ``max_batches`` empty batches in a row."""
        return self._take(count, "_raw", self._refill_raw)

    def _take(self, count: int, buffer: str, refill) -> np.ndarray:
        """(count, n) rows taken in order from the array attribute ``buffer``, in slices, ``refill()`` putting a
        new batch there when it is empty; an error after ``max_batches`` empty refills in a row."""
        if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or not 0 <= count <= MAX_SAMPLES:
            raise ManifoldgenError(f"the number of samples must be a whole number from 0 to {MAX_SAMPLES:,}, got "
                                   f"{count!r}; draw more in several calls")
        rows, need, empty = [], int(count), 0
        while need:
            if not len(getattr(self, buffer)):
                if empty == self.max_batches:
                    raise ManifoldgenError(f"{type(self).__name__} found no valid configuration in "
                                           f"{self.max_batches} batches of {self.batch}")
                refill()
                empty = 0 if len(getattr(self, buffer)) else empty + 1
                continue
            rest = getattr(self, buffer)
            rows.append(rest[:need])
            setattr(self, buffer, rest[need:])
            need -= len(rows[-1])
        return np.concatenate(rows) if rows else np.zeros((0, self.space.n))


def cost_scale(sampler) -> float:
    """The share of a row count that ``sampler`` draws: 1 for a row of at most :data:`REFERENCE_ROW_COST`
    multiply-adds (``row_cost``), less in proportion for a dearer one (the same decode budget)."""
    cost = getattr(sampler, "row_cost", None)
    return min(1.0, REFERENCE_ROW_COST / cost) if cost else 1.0


class UniformSampler(Sampler):
    """Rejection sampling: uniform in the joint limits (almost never on a thin manifold)."""

    def candidates(self, count):
        return self.space.robot.sample_uniform(count, self.rng)


class ProjectionSampler(Sampler):
    """Uniform seeds projected onto the manifold (the projection-based baseline)."""

    lazy_refine = PROJECT_ITERS

    def raw(self, count):
        return self.space.robot.sample_uniform(count, self.rng)

    def candidates(self, count):
        q = self.space.project(self.raw(count), max_iters=self.lazy_refine).q
        self.stats.refined += count
        return q


class DatasetSampler(Sampler):
    """The paper's PG baseline: draws from a dataset's precomputed rows ``q (N, n)`` at this
    condition (``y_rows (N, k)``: the rows' conditions)."""

    def __init__(self, space: ConstrainedSpace, q: np.ndarray, y_rows: np.ndarray, **kwargs):
        super().__init__(space, **kwargs)
        match = np.all(np.isclose(y_rows, space.y, atol=1e-9), axis=1)
        if not match.any():
            values = sorted({tuple(r) for r in np.round(y_rows, 6).tolist()})
            raise ManifoldgenError(f"the dataset has no rows at condition {space.y.tolist()}; "
                                   f"its conditions are {values}")
        self.rows = q[match]

    def candidates(self, count):
        return self.rows[self.rng.integers(0, len(self.rows), size=count)]


class ModelSampler(Sampler):
    """Algorithm 1 with a learned model: batches of model samples at the space's condition,
    refined by at most ``refine`` projection (Levenberg-Marquardt) iterations (default: the model's own
    :attr:`~manifoldgen.models.base.ConditionalSampler.refine`, else ``runtime.REFINE``), checked before
    they are returned. The model's network runs in the compiled core where it can
    (:meth:`~manifoldgen.models.base.ConditionalSampler.native_decoder`), seeded per batch from ``rng``.
    ``model``: a trained model, or a model directory as :func:`manifoldgen.models.open_model` reads it."""

    def __init__(self, space: ConstrainedSpace, model, *, refine: int | None = None, batch: int = 1024,
                 seed: int | np.random.Generator = 0, max_batches: int = 10_000):
        super().__init__(space, batch=batch, seed=seed, max_batches=max_batches)
        refine = (model.refine if model.refine is not None else REFINE) if refine is None else refine
        if refine < 0:
            raise ManifoldgenError(f"refine must be >= 0 projection iterations, got {refine}")
        check_model_for(model, space.constraint)
        model.check_condition(space.y)
        self.model, self.refine = model, int(refine)
        self.decoder = model.native_decoder()  # the model's network in the core, or None: torch runs it
        self.row_cost = model.row_cost()
        self.generator = None
        if not self.decoder:
            import torch

            self.generator = torch.Generator().manual_seed(int(self.rng.integers(0, 2**63 - 1)))
        self.missed = False  # the latest query's start or goal lies far from every model sample
        self.drawn = 0  # raw rows drawn since the latest query began
        from manifoldgen.coverage import spacing
        self.check_rows = self._decode(CHECK_ROWS)  # (CHECK_ROWS, n) model rows at this condition, drawn once
        self.spacing = spacing(self.check_rows)  # their own spacing

    def _batch_rows(self) -> int:
        """Batches grow from :data:`FIRST_ROWS` rows, doubling up to ``batch`` (fewer in proportion for a model
        dearer than the reference, :func:`cost_scale`): an easy query decodes few rows it never uses (a
        flow-matching model's decode costs tens of microseconds a row)."""
        top = max(FIRST_ROWS, round(self.batch * cost_scale(self)))
        return min(top, FIRST_ROWS << min(self.stats.batches, 20))

    @property
    def lazy_refine(self) -> int:
        """Projection iterations per raw row: ``refine``, or the projection sampler's when the query's ends are
        missed (its rows are then mostly uniform seeds, projected lazily as the projection sampler's are)."""
        return PROJECT_ITERS if self.missed else self.refine

    def begin_query(self, start: np.ndarray, goal: np.ndarray) -> str:
        """Measure the gaps from ``start`` and ``goal`` (n,) to the nearest of the :data:`CHECK_ROWS` model rows
        drawn when the sampler was made, against those rows' own spacing (median nearest-neighbour distance); a
        miss (see :func:`manifoldgen.coverage.missed`) makes every batch of this query :data:`MIX_MISSED`
        projected uniform rows. Returns one line saying so, or "" when the model covers both ends. The query
        decodes nothing for it: an easy query draws only its first batch (:data:`FIRST_ROWS`)."""
        from manifoldgen.coverage import gaps, missed

        ends = gaps(self.check_rows, np.stack([start, goal]))
        self.missed = bool(missed(ends, self.spacing).any())
        self.drawn = 0
        if not self.missed:
            return ""
        return (f"the model's samples lie {ends[0]:.2f} rad from the start and {ends[1]:.2f} rad from the goal "
                f"(their own spacing: {self.spacing:.2f} rad): it misses an IK branch of this query, so "
                f"{MIX_MISSED:.0%} of its rows are projected uniform samples; name the scene in the task file, "
                f"recollect (collect seeds around every scene's start and goal) and retrain")

    def mix(self) -> float:
        """The share of projected uniform rows in the next batch (see the module doc)."""
        if self.missed:
            return MIX_MISSED
        return MIX_MAX * float(np.clip(self.drawn / MIX_AFTER - 1.0, 0.0, 1.0))

    def _decode(self, count: int) -> np.ndarray:
        if self.decoder:
            return self.decoder.sample(self.space.y, count, int(self.rng.integers(0, 2**63 - 1)))
        return self.model.sample(self.space.y, count, self.generator)

    def raw(self, count):
        share = self.mix()
        mixed = int(self.rng.binomial(count, share)) if share else 0
        self.drawn += count
        rows = self._decode(count - mixed)
        if not mixed:
            return rows
        uniform = self.space.robot.sample_uniform(mixed, self.rng)
        if not self.missed:  # a query refining rows by `refine` iterations only gets these projected now
            uniform = fast_space(self.space).project(uniform, max_iters=PROJECT_ITERS).q
            self.stats.refined += mixed
        self.stats.mixed += mixed
        return np.concatenate([rows, uniform])[self.rng.permutation(count)]

    def candidates(self, count):
        q = self.raw(count)
        refine = self.lazy_refine
        q = self.space.project(q, max_iters=refine).q if refine else q
        self.stats.refined += count if refine else 0
        return q


def model_sampler(space: ConstrainedSpace, model, *, refine: int | None = None, **common) -> Sampler:
    """The sampler a trained ``model`` stands for in ``space``: its :class:`ModelSampler`, or the projection
    sampler where ``train``'s race found plain projection planned the task's scenes fastest (``model.mix`` 1)
    and no ``refine`` is asked for. ``common``: ``seed``, ``batch``."""
    if model.mix == 1 and refine is None:
        check_model_for(model, space.constraint)
        return ProjectionSampler(space, **common)
    return ModelSampler(space, model, refine=refine, **common)


def generate(model, constraint: Constraint, y: np.ndarray, count: int, generator, refine: int = REFINE,
             ) -> tuple[np.ndarray, np.ndarray]:
    """Raw model rows (count, n) at ``y (k,)`` and the same rows after at most ``refine`` LM iterations."""
    raw = model.sample(y, count, generator)
    return raw, (project(constraint, raw, y, max_iters=refine).q if refine else raw)


MAX_FILE_ROWS = 1_000_000  # rows one `sample` call generates and projects in memory (~1.4 kB each at peak)


def sample_to_file(model, constraint: Constraint, y: np.ndarray, count: int, out, *, seed: int = 0,
                   refine: int = REFINE, source: str = "") -> dict:
    """Generate ``count`` rows at ``y``, write them in the dataset format (raw rows when refine=0,
    refined rows otherwise, as ``meta['rows']`` says) and return the raw and refined valid rates."""
    import torch

    from manifoldgen.io import check_output_path, save_npz

    if not 0 < count <= MAX_FILE_ROWS:
        raise ManifoldgenError(f"-n must be a positive number of samples, at most {MAX_FILE_ROWS:,} (memory grows "
                               f"with it), got {count}; write larger sets as several files with different --seed")
    seed = check_seed(seed)
    if refine < 0:
        raise ManifoldgenError(f"--refine must be >= 0 projection iterations, got {refine}")
    out = check_output_path(out, kind="samples")
    check_model_for(model, constraint, f"model {source}" if source else "the model")
    y = np.asarray(y, float).reshape(constraint.condition.k)
    raw, refined = generate(model, constraint, y, count, torch.Generator().manual_seed(seed), refine)
    y_rows = np.broadcast_to(y, (count, len(y))).copy()
    space = ConstrainedSpace(constraint, y)
    rates = {"raw_valid_rate": float(space.valid(raw).mean()), "refined_valid_rate": float(space.valid(refined).mean())}
    meta = {**model.meta, "dataset_seed": model.meta.get("seed"), "seed": seed,
            "rows": "refined" if refine else "raw", "refine": refine,
            "generated_by": {"model": model.label, "source": source}, **rates}
    save_npz(out, meta, q=refined if refine else raw, y=y_rows)
    return {**rates, "rows": meta["rows"], "count": count}
