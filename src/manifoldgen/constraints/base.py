"""The constraint contract: batched residuals F(q, y) = 0 and inequalities G(q, y) <= 0.

A new constraint subclasses :class:`Constraint`, implements ``residual`` and
``jacobian`` (and optionally ``inequality``) for batches, and describes itself in
``spec()``; projection, collection, samplers and planners need nothing else.
"""

from __future__ import annotations

import itertools
import warnings
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot, as_batch


@dataclass(frozen=True)
class Condition:
    """The task parameters ``y (k,)`` a constraint is conditioned on.

    values: the training values (V, k) a dataset is collected at; low/high: the range
    inside which a model may be asked for samples.
    """

    names: tuple[str, ...]
    units: tuple[str, ...]
    values: np.ndarray = field(repr=False)

    @property
    def k(self) -> int:
        return len(self.names)

    @property
    def low(self) -> np.ndarray:
        return np.asarray(self.values, float).reshape(-1, self.k).min(axis=0)

    @property
    def high(self) -> np.ndarray:
        return np.asarray(self.values, float).reshape(-1, self.k).max(axis=0)

    def describe(self) -> str:
        return ", ".join(f"{n} in [{lo:g}, {hi:g}] {u}"
                         for n, u, lo, hi in zip(self.names, self.units, self.low, self.high))

    def check(self, y: np.ndarray, strict: bool = False, margin: float = 1e-9) -> np.ndarray:
        """Return y as (B, k); outside the range: warn, or raise when strict."""
        y = np.atleast_2d(np.asarray(y, dtype=float))
        if y.shape[1] != self.k:
            raise ManifoldgenError(f"condition needs {self.k} value(s) ({', '.join(self.names)}), "
                                   f"got {y.shape[1]}")
        if not np.all(np.isfinite(y)):
            raise ManifoldgenError("condition contains NaN or infinite values")
        outside = np.any((y < self.low - margin) | (y > self.high + margin), axis=1)
        if outside.any():
            msg = (f"condition {y[outside][0].tolist()} is outside the trained range "
                   f"({self.describe()})")
            if strict:
                raise ManifoldgenError(msg + "; choose a value inside it or drop --strict")
            warnings.warn(msg + "; results may be poor", stacklevel=2)
        return y


class Constraint(ABC):
    """Equality residuals F(q, y) (B, m) with per-component tolerance, inequalities G (B, p)."""

    robot: Robot
    condition: Condition
    tolerance: np.ndarray  # (m,)

    @abstractmethod
    def residual(self, q: np.ndarray, y: np.ndarray) -> np.ndarray:
        """F(q, y): (B, m)."""

    @abstractmethod
    def jacobian(self, q: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """F (B, m) and dF/dq (B, m, n) in one pass."""

    def inequality(self, q: np.ndarray, y: np.ndarray) -> np.ndarray:
        """G(q, y) <= 0: (B, p); none by default."""
        return np.zeros((len(np.atleast_2d(q)), 0))

    @abstractmethod
    def spec(self) -> dict:
        """JSON-ready full specification (type, frames, targets, tolerances)."""

    @property
    def m(self) -> int:
        return len(self.tolerance)

    def batch(self, q: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Promote q to (B, n) and broadcast y to (B, k)."""
        q = as_batch(q, self.robot.n)
        y = np.asarray(y, dtype=float)
        y = np.broadcast_to(y.reshape(-1, self.condition.k), (len(q), self.condition.k))
        return q, y

    def violation(self, q: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(B,) worst ratio |F_i| / tol_i (<= 1 means within tolerance)."""
        return np.max(np.abs(self.residual(q, y)) / self.tolerance, axis=1)

    def satisfied(self, q: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(B,) bool: equalities within tolerance, inequalities <= 0, inside joint limits."""
        q, y = self.batch(q, y)
        ok = self.violation(q, y) <= 1.0
        G = self.inequality(q, y)
        if G.shape[1]:
            ok &= np.all(G <= 0, axis=1)
        return ok & self.robot.within_limits(q)


class ConstraintSet(Constraint):
    """Several constraints on one robot, holding together.

    y is the parts' conditions concatenated; the training values are their grid (product).
    """

    def __init__(self, constraints: list[Constraint]):
        if not constraints:
            raise ManifoldgenError("a ConstraintSet needs at least one constraint")
        self.parts = list(constraints)
        self.robot = constraints[0].robot
        self.condition = Condition(
            sum((c.condition.names for c in constraints), ()),
            sum((c.condition.units for c in constraints), ()),
            np.array([np.concatenate(rows) for rows in itertools.product(
                *[np.asarray(c.condition.values, float).reshape(-1, c.condition.k) for c in constraints])]))
        self.tolerance = np.concatenate([c.tolerance for c in constraints])

    def _split(self, y: np.ndarray) -> list[np.ndarray]:
        cuts = np.cumsum([c.condition.k for c in self.parts])[:-1]
        return np.split(y, cuts, axis=1)

    def residual(self, q, y):
        q, y = self.batch(q, y)
        return np.concatenate([c.residual(q, yc) for c, yc in zip(self.parts, self._split(y))], axis=1)

    def jacobian(self, q, y):
        q, y = self.batch(q, y)
        pairs = [c.jacobian(q, yc) for c, yc in zip(self.parts, self._split(y))]
        return np.concatenate([F for F, _ in pairs], axis=1), np.concatenate([J for _, J in pairs], axis=1)

    def inequality(self, q, y):
        q, y = self.batch(q, y)
        return np.concatenate([c.inequality(q, yc) for c, yc in zip(self.parts, self._split(y))], axis=1)

    def spec(self) -> dict:
        return {"type": "set", "parts": [c.spec() for c in self.parts]}
