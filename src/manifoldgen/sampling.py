"""Samplers: what planners draw configurations from.

Every sampler serves one fixed condition ``y`` and returns, from ``sample()``, one
configuration ``(n,)`` that satisfies the constraint (and is collision-free when a
``CollisionChecker`` is given). Candidates are produced in batches and kept in a
buffer, as in the paper's Algorithm 1; ``stats`` counts what it cost.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass

import numpy as np

from manifoldgen.collision import CollisionChecker
from manifoldgen.constraints import Constraint, project
from manifoldgen.errors import ManifoldgenError


@dataclass
class SamplerStats:
    """Counts since construction: candidates made, projected, accepted; batches drawn."""

    generated: int = 0
    refined: int = 0
    accepted: int = 0
    batches: int = 0

    def to_dict(self) -> dict:
        return asdict(self)


class Sampler(ABC):
    """Algorithm 1: pop buffered candidates, return the first valid one, refill when empty."""

    def __init__(self, constraint: Constraint, y: np.ndarray, *, checker: CollisionChecker | None = None,
                 batch: int = 256, seed: int | np.random.Generator = 0, max_batches: int = 10_000):
        self.constraint, self.checker = constraint, checker
        self.y = np.asarray(y, dtype=float).reshape(constraint.condition.k)
        self.batch, self.max_batches = batch, max_batches
        self.rng = np.random.default_rng(seed)
        self.stats = SamplerStats()
        self._buffer = np.zeros((0, constraint.robot.n))

    @abstractmethod
    def candidates(self, count: int) -> np.ndarray:
        """(count, n) new candidate configurations (not yet checked)."""

    def valid(self, q: np.ndarray) -> np.ndarray:
        """(B,) bool: constraint satisfied and, with a checker, collision-free."""
        ok = self.constraint.satisfied(q, self.y)
        if self.checker is not None and ok.any():
            ok[ok] = ~self.checker.in_collision(q[ok])
        return ok

    def _refill(self) -> None:
        q = self.candidates(self.batch)
        self.stats.generated += len(q)
        self.stats.batches += 1
        self._buffer = q[self.valid(q)]

    def sample(self) -> np.ndarray:
        """One valid configuration (n,)."""
        for _ in range(self.max_batches):
            if len(self._buffer):
                q, self._buffer = self._buffer[0], self._buffer[1:]
                self.stats.accepted += 1
                return q
            self._refill()
        raise ManifoldgenError(f"{type(self).__name__} found no valid configuration in "
                               f"{self.max_batches} batches of {self.batch}")

    def sample_many(self, count: int) -> np.ndarray:
        """(count, n) valid configurations."""
        return np.stack([self.sample() for _ in range(count)]) if count else np.zeros((0, self.constraint.robot.n))


class UniformSampler(Sampler):
    """Rejection sampling: uniform in the joint limits (almost never on a thin manifold)."""

    def candidates(self, count):
        return self.constraint.robot.sample_uniform(count, self.rng)


class ProjectionSampler(Sampler):
    """Uniform seeds projected onto the manifold (the projection-based baseline)."""

    def candidates(self, count):
        q = project(self.constraint, self.constraint.robot.sample_uniform(count, self.rng), self.y).q
        self.stats.refined += count
        return q


class DatasetSampler(Sampler):
    """The paper's PG baseline: draws from a dataset's precomputed rows at this condition."""

    def __init__(self, constraint, y, q: np.ndarray, y_rows: np.ndarray, **kwargs):
        super().__init__(constraint, y, **kwargs)
        match = np.all(np.isclose(y_rows, self.y, atol=1e-9), axis=1)
        if not match.any():
            values = sorted({tuple(r) for r in np.round(y_rows, 6).tolist()})
            raise ManifoldgenError(f"the dataset has no rows at condition {self.y.tolist()}; "
                                   f"its conditions are {values}")
        self.rows = q[match]

    def candidates(self, count):
        return self.rows[self.rng.integers(0, len(self.rows), size=count)]
