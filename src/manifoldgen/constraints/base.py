"""The constraint contract: batched residuals F(q, y) = 0 and inequalities G(q, y) <= 0.

A constraint is written once. A subclass sets ``robot``, ``condition`` and ``tolerance`` in
its ``__init__`` and implements ``residual`` (and optionally ``inequality``) with array
operations that work on numpy arrays and on torch tensors alike: ``xp = array_namespace(q)``
gives the namespace (``xp.concat``, ``xp.sin``, ...), ``Robot.frame_pose`` and ``Robot.com``
take either, and :func:`as_like` turns a numpy constant into the backend of an array. That
one residual serves projection and planning (float64 numpy, with a Jacobian from torch
autograd unless the class gives an analytic one) and the models' training penalty (torch,
differentiable). The constructor's arguments are recorded, so ``spec()`` describes the
constraint fully and :func:`build_constraint` rebuilds it from that spec.
"""

from __future__ import annotations

import inspect
import itertools
import math
import warnings
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import array_api_compat
import numpy as np

from manifoldgen.errors import ManifoldgenError, short
from manifoldgen.registry import Registry
from manifoldgen.constraints import trace
from manifoldgen.robot import Robot, as_batch, is_tensor, is_traced

def array_namespace(*arrays):
    """The array API namespace of ``arrays``: numpy itself for numpy arrays (numpy 2 follows the standard, and the
    compat wrapper costs a command 0.15-0.3 s to import), array_api_compat's namespace otherwise (torch, traced)."""
    if all(isinstance(a, np.ndarray) for a in arrays):
        return np
    return array_api_compat.array_namespace(*arrays)


MIN_TOLERANCE = 1e-5  # m or rad: ten times the residual at which projection stops (constraints/projection.py)
INEQUALITY_SCALE = 0.01  # G (metres or radians) per unit of the training penalty, like a tolerance
MAX_CONDITION_VALUES = 100_000  # condition values one task may train at (a set's: the product of its parts')


@dataclass(frozen=True)
class Condition:
    """The task parameters ``y (k,)`` a constraint is conditioned on.

    values: the training values (V, k) a dataset is collected at; low/high: the range
    inside which a model may be asked for samples.
    """

    names: tuple[str, ...]
    units: tuple[str, ...]
    values: np.ndarray = field(repr=False)

    def __post_init__(self):
        try:
            width = np.shape(self.values)[1:]
            if self.k and width not in ((), (self.k,)):
                raise IndexError
            grid = self.grid
        except IndexError:
            raise ManifoldgenError(f"values rows must hold {self.k} number(s) ({', '.join(self.names)}), got "
                                   f"{' x '.join(map(str, width))}") from None
        except (TypeError, ValueError):
            raise ManifoldgenError(f"condition values must be {self.k} number(s) per row ({', '.join(self.names)}), "
                                   f"got {short(np.asarray(self.values, dtype=object).tolist(), 60)}") from None
        if not np.isfinite(grid).all():
            raise ManifoldgenError(f"condition values must be finite numbers, got {grid.tolist()}")
        if self.k and not len(grid):
            raise ManifoldgenError(f"condition values must hold at least one value of {', '.join(self.names)}, got "
                                   "none; give values = [[v1], [v2], ...]")
        if len(grid) > MAX_CONDITION_VALUES:
            raise ManifoldgenError(f"{len(grid):,} condition values of {', '.join(self.names)}: at most "
                                   f"{MAX_CONDITION_VALUES:,} (a model trains on rows at each); give fewer values")
        seen: set[tuple] = set()
        twice = next((row for row in map(tuple, grid.tolist()) if row in seen or seen.add(row)), None)
        if self.k and twice is not None:
            raise ManifoldgenError(f"condition value {list(twice)} is given twice in values; give each once")

    @property
    def k(self) -> int:
        return len(self.names)

    @property
    def grid(self) -> np.ndarray:
        """The training values as (V, k); one empty row when nothing is conditioned (k = 0)."""
        return np.asarray(self.values, float).reshape(-1, self.k) if self.k else np.zeros((1, 0))

    @property
    def low(self) -> np.ndarray:
        return self.grid.min(axis=0)

    @property
    def high(self) -> np.ndarray:
        return self.grid.max(axis=0)

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
            raise ManifoldgenError(f"condition {y[~np.isfinite(y).all(axis=1)][0].tolist()} is not finite; give "
                                   f"numbers inside {self.describe()}")
        outside = np.any((y < self.low - margin) | (y > self.high + margin), axis=1)
        if outside.any():
            rows = np.unique(y[outside], axis=0).tolist()
            more = f" and {len(rows) - 3} more" if len(rows) > 3 else ""
            said = "condition {} is" if len(rows) == 1 else "conditions {} are"
            msg = f"{said.format(', '.join(map(str, rows[:3])) + more)} outside the trained range ({self.describe()})"
            if strict:
                raise ManifoldgenError(msg + "; choose a value inside it or drop --strict")
            warnings.warn(msg + "; results may be poor", stacklevel=2)
        return y


def as_like(value, like):
    """``value`` (a numpy constant) as an array of ``like``'s backend and dtype."""
    if is_tensor(like):
        import torch
        return torch.as_tensor(np.asarray(value), dtype=like.dtype)
    return np.asarray(value, dtype=float)


class Constraint(ABC):
    """Equality residuals F(q, y) (B, m) with per-component tolerance, inequalities G (B, p).

    Subclasses set ``robot``, ``condition`` and ``tolerance (m,)`` and implement ``residual``
    for numpy arrays and torch tensors (see the module doc); ``jacobian`` may be overridden
    with an analytic one for speed.
    """

    robot: Robot
    condition: Condition
    tolerance: np.ndarray  # (m,)
    arguments: dict  # the constructor's arguments (robot excluded), recorded by __new__

    def __new__(cls, *args, **kwargs):
        obj = super().__new__(cls)
        bound = inspect.signature(cls.__init__).bind(obj, *args, **kwargs)
        bound.apply_defaults()
        obj.arguments = {k: v for k, v in list(bound.arguments.items())[1:] if not isinstance(v, Robot)}
        return obj

    @abstractmethod
    def residual(self, q, y):
        """F(q, y): (B, m), for numpy ``q (B, n)``, ``y (B, k)`` or torch tensors of those shapes."""

    def jacobian(self, q: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """F (B, m) and dF/dq (B, m, n) in one pass (float64 torch autograd of ``residual``)."""
        import torch

        q, y = self.batch(q, y)
        qt = torch.as_tensor(q, dtype=torch.float64).requires_grad_(True)
        F = self.residual(qt, torch.tensor(y, dtype=torch.float64))
        rows = []
        for i in range(F.shape[1]):
            (g,) = torch.autograd.grad(F[:, i].sum(), qt, retain_graph=True, allow_unused=True)
            rows.append(torch.zeros_like(qt) if g is None else g)
        J = torch.stack(rows, dim=1) if rows else torch.zeros(len(q), 0, q.shape[1], dtype=torch.float64)
        return F.detach().numpy(), J.numpy()

    def inequality(self, q, y):
        """G(q, y) <= 0: (B, p), numpy or torch like ``q``; none by default."""
        xp = array_namespace(q)
        return xp.zeros((q.shape[0], 0), dtype=q.dtype)

    def core_terms(self, y: np.ndarray) -> list[dict] | None:
        """This constraint at its condition ``y (k,)`` as the compiled core's terms, in residual order
        (JSON-ready dicts: ``type`` and its fields, see :func:`manifoldgen.core_terms.constraint_terms`), or None where
        the core has no term of its own for it (a user's constraint: its residual is compiled from its trace, or
        called back)."""
        return None

    def spec(self) -> dict:
        """JSON-ready full specification: ``type`` (registered name or ``module:Class``) and the
        constructor's arguments; :func:`build_constraint` rebuilds the constraint from it."""
        return {"type": CONSTRAINTS.name_of(type(self)), **{k: _jsonable(v) for k, v in self.arguments.items()}}

    @classmethod
    def from_spec(cls, robot: Robot, arguments: dict) -> Constraint:
        """Rebuild from the constructor arguments ``spec()`` recorded."""
        return cls(robot, **arguments)

    @property
    def m(self) -> int:
        return len(self.tolerance)

    def batch(self, q, y):
        """Promote q to (B, n) and broadcast y to (B, k), numpy or torch like ``q``."""
        k = self.condition.k
        rows = (-1, k) if k else (1, 0)  # (-1, 0) is ambiguous
        if is_traced(q):  # recorded for the compiled core (constraints/trace.py)
            return trace.batch(q, y, self.robot.n, k)
        if is_tensor(q):
            import torch
            q = q if q.ndim == 2 else q[None]
            return q, torch.as_tensor(y, dtype=q.dtype).reshape(rows).expand(len(q), k)
        q = as_batch(q, self.robot.n)
        return q, np.broadcast_to(np.asarray(y, dtype=float).reshape(rows), (len(q), k))

    def violation(self, q: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(B,) worst ratio |F_i| / tol_i (<= 1 means within tolerance)."""
        q, y = self.batch(q, y)
        if not self.m:
            return np.zeros(len(q))
        return np.max(np.abs(self.residual(q, y)) / self.tolerance, axis=1)

    def satisfied(self, q: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(B,) bool: equalities within tolerance, inequalities <= 0, inside joint limits."""
        q, y = self.batch(q, y)
        ok = self.violation(q, y) <= 1.0
        G = self.inequality(q, y)
        if G.shape[1]:
            ok &= np.all(G <= 0, axis=1)
        return ok & self.robot.within_limits(q)

    def penalty(self, q, y):
        """(B,) differentiable ``sum_i (F_i / tol_i)^2 + sum_j (max(G_j, 0) / INEQUALITY_SCALE)^2`` for
        torch ``q (B, n)``, ``y (B, k)``: the models' training penalty, for every constraint alike."""
        q, y = self.batch(q, y)
        with self.robot.torch_kinematics.shared():  # the frames residual and inequality share: computed once
            F = self.residual(q, y) / as_like(self.tolerance, q)
            G = self.inequality(q, y)
        return (F * F).sum(dim=1) + (G.clamp(min=0) / INEQUALITY_SCALE).pow(2).sum(dim=1)


CONSTRAINTS: Registry[Constraint] = Registry("constraint", Constraint)


def build_constraint(robot: Robot, spec: dict) -> Constraint:
    """The constraint ``spec`` describes (as :meth:`Constraint.spec` wrote it), on ``robot``."""
    if not isinstance(spec, dict) or "type" not in spec:
        raise ManifoldgenError(f"a constraint needs a 'type' (one of {', '.join(CONSTRAINTS.names())} or "
                               f"'module:Class'), got {spec!r}")
    cls = CONSTRAINTS.get(str(spec["type"]))
    arguments = {k: v for k, v in spec.items() if k != "type"}
    check_arguments(cls, arguments, str(spec["type"]))
    try:
        constraint = cls.from_spec(robot, arguments)
    except TypeError as exc:
        params = [p for p in inspect.signature(cls.__init__).parameters if p not in ("self", "robot")]
        raise ManifoldgenError(f"constraint '{spec['type']}': {exc}; its parameters are {', '.join(params)}") from exc
    condition = getattr(constraint, "condition", None)
    if not isinstance(condition, Condition):
        raise ManifoldgenError(f"constraint '{spec['type']}': its condition must be a manifoldgen.constraints."
                               f"Condition, got {type(condition).__name__}; set self.condition = Condition(names, "
                               "units, values) in its __init__")
    try:
        tolerance = np.asarray(getattr(constraint, "tolerance", []), dtype=float).reshape(-1)
    except (TypeError, ValueError):
        tolerance = np.array([np.nan])
    if not np.all((tolerance >= MIN_TOLERANCE) & (tolerance <= 1)):  # NaN fails too
        raise ManifoldgenError(f"constraint '{spec['type']}': its tolerances must be positive and finite, from "
                               f"{MIN_TOLERANCE:g} to 1 (m or rad: a wider one accepts almost any configuration, a "
                               f"tighter one none), got {short(tolerance.tolist(), 60)}")
    return constraint


def check_arguments(cls: type, arguments: dict, name: str) -> None:
    """Refuse, in one line, a constructor argument of the wrong kind for what its signature says: a string or a
    number where a list belongs (a string would be read letter by letter), a non-number, NaN or infinity where a
    number belongs (a ``*tolerance`` must be positive, a ``margin`` at least 0), anything but true or false for
    a flag, and a non-string for a name. Parameters that say nothing (no default, no annotation) are left to the
    constructor."""
    parameters = inspect.signature(cls.__init__).parameters
    for key, value in arguments.items():
        p = parameters.get(key)
        if p is None or p.kind in (p.VAR_KEYWORD, p.VAR_POSITIONAL):
            continue
        default, note = p.default, str(p.annotation)
        if isinstance(default, bool) or note == "bool":
            ok, need = isinstance(value, bool), "true or false"
        elif isinstance(default, float) or note == "float":
            number = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
            if not number:
                ok, need = False, "a finite number" + (" (written without quotes)" if isinstance(value, str) else "")
            elif key.endswith("tolerance"):
                ok, need = value >= MIN_TOLERANCE, (f"at least {MIN_TOLERANCE:g} (projection stops at a "
                                                               "residual of 1e-6: a tighter one rejects every row)")
                if ok and value > 1:
                    ok, need = False, "at most 1 (m or rad: a wider one accepts almost any configuration)"
            elif key == "margin":
                ok, need = value >= 0, "a number >= 0"
            else:
                ok, need = True, ""
        elif isinstance(default, (tuple, list)) or note.startswith(("list", "tuple")):
            ok, need = isinstance(value, (list, tuple)), "a list (e.g. [\"z\"] or [0.0, 0.0, 1.0])"
        elif isinstance(default, str) or note.startswith("str"):
            ok, need = isinstance(value, str) or (value is None and default is None), "a string"
        else:
            continue
        if not ok:
            raise ManifoldgenError(f"constraint '{name}': {key} must be {need}, got {value!r}")


def _jsonable(value):
    if isinstance(value, Constraint):
        return value.spec()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    return value


@CONSTRAINTS.register("set")
class ConstraintSet(Constraint):
    """Several constraints on one robot, holding together.

    y is the parts' conditions concatenated; the training values are their grid (product).
    """

    def __init__(self, parts: list[Constraint]):
        if not parts:
            raise ManifoldgenError("a constraint set needs at least one constraint")
        self.parts = list(parts)
        self.robot = parts[0].robot
        combinations = math.prod(len(c.condition.grid) for c in parts)
        if combinations > MAX_CONDITION_VALUES:
            raise ManifoldgenError(f"the parts' condition values make {combinations:,} combinations (the product of "
                                   f"{' x '.join(str(len(c.condition.grid)) for c in parts)}), over "
                                   f"{MAX_CONDITION_VALUES:,}; give the parts fewer values")
        self.condition = Condition(
            sum((c.condition.names for c in parts), ()), sum((c.condition.units for c in parts), ()),
            np.array([np.concatenate(rows) for rows in itertools.product(*[c.condition.grid for c in parts])]))
        self.tolerance = np.concatenate([c.tolerance for c in parts])
        cuts = np.cumsum([0] + [c.condition.k for c in parts])
        self._slices = [slice(int(a), int(b)) for a, b in zip(cuts[:-1], cuts[1:])]

    @classmethod
    def from_spec(cls, robot, arguments):
        return cls([build_constraint(robot, part) for part in arguments.get("parts", [])])

    def residual(self, q, y):
        q, y = self.batch(q, y)
        xp = array_namespace(q)
        return xp.concat([c.residual(q, y[:, s]) for c, s in zip(self.parts, self._slices)], axis=1)

    def jacobian(self, q, y):
        q, y = self.batch(q, y)
        pairs = [c.jacobian(q, y[:, s]) for c, s in zip(self.parts, self._slices)]
        return np.concatenate([F for F, _ in pairs], axis=1), np.concatenate([J for _, J in pairs], axis=1)

    def inequality(self, q, y):
        q, y = self.batch(q, y)
        xp = array_namespace(q)
        return xp.concat([c.inequality(q, y[:, s]) for c, s in zip(self.parts, self._slices)], axis=1)


def own_jacobian(constraint: Constraint) -> bool:
    """Whether ``constraint`` (each part of a set) computes its Jacobian itself, not by the default torch autograd
    (whose import costs 2-3 s, and whose per-operation overhead dominates on small batches)."""
    parts = constraint.parts if isinstance(constraint, ConstraintSet) else [constraint]
    return all(type(part).jacobian is not Constraint.jacobian for part in parts)
