"""A constraint's residual traced once into a program the compiled core runs per configuration.

:func:`trace` calls a constraint's ``residual`` and ``inequality`` once with :class:`Traced` arrays in place of
``q (B, n)`` and ``y (B, k)``. A traced array records the operations done on it instead of doing them: every
element is a scalar register of a graph whose leaves are ``q``'s coordinates, the world position (3) and rotation
(3 x 3) of each frame ``robot.frame_pose(q, frame)`` is asked for, and the centre of mass ``robot.com(q)``; the
condition ``y`` is baked in as constants, as the core's built-in terms have it. Constants are folded, repeated
operations shared, and what no output needs dropped. The result is a :class:`Program`: straight-line code on scalar
registers that the core (``native/src/expression.cpp``) evaluates with forward-mode derivatives, so a user's
residual needs no Python call per state.

Recorded: indexing and slicing of every axis but the batch axis (integer lists included), ``+ - * / **``, unary
minus and ``abs`` with scalars and broadcast arrays, ``@`` and ``matmul``, ``.T`` (of constants), ``.mT``,
``matrix_transpose``, ``permute_dims``, ``reshape``, ``expand_dims``, ``squeeze``, ``sum``, ``prod``, ``mean``,
``max``, ``min``, ``concat``/``stack``, ``sqrt``, ``square``, ``sin``, ``cos``, ``tan``, ``asin``, ``acos``,
``atan``, ``atan2``, ``exp``, ``log``, ``tanh``, ``pow``, ``maximum``, ``minimum``, ``clip``, ``vecdot``,
``linalg.vector_norm`` (2-norm), ``linalg.cross``, ``asarray``/``zeros``/``ones``/``full`` (``_like`` too) and
numpy constants (``as_like``). Anything else (comparisons, ``where``, a Python branch on a value, a numpy
function called directly, another robot method, an operation across the batch axis) raises :class:`Untraceable`
with the reason; the caller then keeps the constraint in Python.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass

import numpy as np

# The operations a program may hold (the core's manifoldgen_core.Op names) and how Python folds constants.
LEAVES = ("Q", "CONST", "POS", "ROT", "COM")
UNARY = {"NEG": operator.neg, "SQRT": math.sqrt, "SIN": math.sin, "COS": math.cos, "TAN": math.tan,
         "ASIN": math.asin, "ACOS": math.acos, "ATAN": math.atan, "EXP": math.exp, "LOG": math.log, "ABS": abs,
         "TANH": math.tanh}
BINARY = {"ADD": operator.add, "SUB": operator.sub, "MUL": operator.mul, "DIV": operator.truediv,
          "POW": operator.pow, "ATAN2": math.atan2, "MAX": np.maximum, "MIN": np.minimum}  # NaN in, NaN out
OPS = LEAVES + tuple(UNARY) + tuple(BINARY)
_COMMUTATIVE = {"ADD", "MUL", "MAX", "MIN"}
# results that are finite whenever their operands are (x * 0 folds to 0 only for such an x: NaN * 0 is NaN)
_FINITE = {"Q", "POS", "ROT", "COM", "NEG", "SIN", "COS", "ATAN", "ABS", "TANH", "ADD", "SUB", "MUL", "MAX", "MIN"}


class Untraceable(Exception):
    """The residual uses something the tracer does not record; the message says what."""


@dataclass(frozen=True)
class Program:
    """Straight-line code: register i is ``code[i]``'s result, an (op, a, b) row with the operands of
    ``manifoldgen_core.Op``; ``constants``; ``frames``: pinocchio frame ids by slot (POS and ROT name a slot);
    ``outputs``: the registers of the result's rows."""

    code: tuple[tuple[str, int, int], ...]
    constants: tuple[float, ...]
    frames: tuple[int, ...]
    outputs: tuple[int, ...]

    @property
    def rows(self) -> int:
        return len(self.outputs)


class _Graph:
    """The recorded scalar operations: nodes (op, a, b), shared when repeated; a, b are node indices for unary
    and binary operations, a constant's index, a coordinate, a frame id and axis for the leaves."""

    def __init__(self, robot):
        self.robot = robot
        self.nodes: list[tuple[str, int, int]] = []
        self.constants: list[float] = []
        self.value: list[float | None] = []  # per node: its value when it is a constant
        self.finite: list[bool] = []
        self._index: dict[tuple, int] = {}
        self.q: np.ndarray | None = None  # the traced q's elements

    def _add(self, op: str, a: int, b: int, value: float | None = None, finite: bool = False) -> _Node:
        key = (op, a, b)
        if key not in self._index:
            self._index[key] = len(self.nodes)
            self.nodes.append(key)
            self.value.append(value)
            self.finite.append(finite)
        return _Node(self, self._index[key])

    def const(self, value) -> _Node:
        value = float(value)
        bits = np.float64(value).tobytes()  # -0.0 and 0.0 apart, NaN as itself
        key = ("CONST", bits)
        if key not in self._index:
            self._index[key] = len(self.nodes)
            self.nodes.append(("CONST", len(self.constants), 0))
            self.constants.append(value)
            self.value.append(value)
            self.finite.append(math.isfinite(value))
        return _Node(self, self._index[key])

    def leaf(self, op: str, a: int, b: int = 0) -> _Node:
        return self._add(op, a, b, finite=True)

    def node(self, x) -> _Node:
        if isinstance(x, _Node):
            if x.graph is not self:
                raise Untraceable("arrays of two different traces are mixed")
            return x
        if isinstance(x, (bool, int, float, np.integer, np.floating, np.bool_)):
            return self.const(x)
        raise Untraceable(f"an operand of type {type(x).__name__}")

    def unary(self, op: str, x) -> _Node:
        x = self.node(x)
        value = self.value[x.index]
        if value is not None:
            return self.const(_fold(UNARY[op], value))
        if op == "NEG" and self.nodes[x.index][0] == "NEG":
            return _Node(self, self.nodes[x.index][1])
        return self._add(op, x.index, 0, finite=op in _FINITE and self.finite[x.index])

    def binary(self, op: str, x, y) -> _Node:
        x, y = self.node(x), self.node(y)
        vx, vy = self.value[x.index], self.value[y.index]
        if vx is not None and vy is not None:
            return self.const(_fold(BINARY[op], vx, vy))
        if op in ("ADD", "SUB") and vy == 0.0:
            return x
        if op == "ADD" and vx == 0.0:
            return y
        if op == "SUB" and vx == 0.0:
            return self.unary("NEG", y)
        if op == "MUL":
            for other, v in ((y, vx), (x, vy)):
                if v == 1.0:
                    return other
                if v == -1.0:
                    return self.unary("NEG", other)
                if v == 0.0 and self.finite[other.index]:
                    return self.const(0.0)
        if op == "DIV" and vy == 1.0:
            return x
        if op == "POW" and vy in (1.0, 2.0):
            return x if vy == 1.0 else self.binary("MUL", x, x)
        a, b = x.index, y.index
        if op in _COMMUTATIVE and a > b:
            a, b = b, a
        return self._add(op, a, b, finite=op in _FINITE and self.finite[a] and self.finite[b])

    def program(self, outputs: list[_Node]) -> Program:
        """The nodes the outputs need, renumbered in order, frame ids turned into slots."""
        needed = [False] * len(self.nodes)
        stack = [x.index for x in outputs]
        while stack:
            i = stack.pop()
            if needed[i]:
                continue
            needed[i] = True
            op, a, b = self.nodes[i]
            if op in UNARY:
                stack.append(a)
            elif op in BINARY:
                stack += [a, b]
        order, code, constants, frames = {}, [], [], {}
        for i, keep in enumerate(needed):
            if not keep:
                continue
            op, a, b = self.nodes[i]
            if op == "CONST":
                a, constants = len(constants), constants + [self.constants[a]]
            elif op in ("POS", "ROT"):
                a = frames.setdefault(a, len(frames))
            elif op in UNARY:
                a = order[a]
            elif op in BINARY:
                a, b = order[a], order[b]
            order[i] = len(code)
            code.append((op, a, b))
        return Program(tuple(code), tuple(constants), tuple(frames), tuple(order[x.index] for x in outputs))

    # leaves
    def frame_pose(self, robot, frame, q: Traced) -> tuple[Traced, Traced]:
        self._kinematics_of(robot, q, "frame_pose")
        fid = robot.frame_id(frame)
        p = np.array([self.leaf("POS", fid, i) for i in range(3)], dtype=object)
        R = np.array([self.leaf("ROT", fid, i) for i in range(9)], dtype=object).reshape(3, 3)
        return Traced(p, True), Traced(R, True)

    def com(self, robot, q: Traced) -> Traced:
        self._kinematics_of(robot, q, "com")
        return Traced(np.array([self.leaf("COM", 0, i) for i in range(3)], dtype=object), True)

    def _kinematics_of(self, robot, q: Traced, what: str) -> None:
        if robot is not self.robot:
            raise Untraceable(f"{what} of a robot other than the constraint's")
        if not (q._batched and q._e.shape == self.q.shape
                and all(isinstance(a, _Node) and a.index == b.index for a, b in zip(q._e, self.q))):
            raise Untraceable(f"{what} of an array other than the traced q")


def _fold(f, *values: float) -> float:
    try:
        return float(f(*values))
    except (ValueError, ZeroDivisionError, OverflowError) as exc:
        raise Untraceable(f"a constant expression fails in Python ({exc})") from exc


class _Node:
    """One scalar of a traced array: its graph and node index; Python's operators record operations."""

    __slots__ = ("graph", "index")
    __array_ufunc__ = None  # numpy defers to the reflected operators

    def __init__(self, graph: _Graph, index: int):
        self.graph, self.index = graph, index

    def __add__(self, other):
        return self.graph.binary("ADD", self, other)

    def __radd__(self, other):
        return self.graph.binary("ADD", other, self)

    def __sub__(self, other):
        return self.graph.binary("SUB", self, other)

    def __rsub__(self, other):
        return self.graph.binary("SUB", other, self)

    def __mul__(self, other):
        return self.graph.binary("MUL", self, other)

    def __rmul__(self, other):
        return self.graph.binary("MUL", other, self)

    def __truediv__(self, other):
        return self.graph.binary("DIV", self, other)

    def __rtruediv__(self, other):
        return self.graph.binary("DIV", other, self)

    def __pow__(self, other):
        return self.graph.binary("POW", self, other)

    def __rpow__(self, other):
        return self.graph.binary("POW", other, self)

    def __neg__(self):
        return self.graph.unary("NEG", self)

    def __pos__(self):
        return self

    def __abs__(self):
        return self.graph.unary("ABS", self)

    def __bool__(self):
        raise Untraceable("a Python branch or comparison on a traced value")

    def __float__(self):
        raise Untraceable("a traced value turned into a Python number")

    __int__ = __index__ = __float__


def _element_graph(e: np.ndarray) -> _Graph | None:
    for x in e.flat:
        if isinstance(x, _Node):
            return x.graph
    return None


def _objects(x) -> np.ndarray:
    """``x`` as an object array (a 0-d one for a scalar)."""
    if isinstance(x, np.ndarray) and x.dtype == object:
        return x
    out = np.empty(np.shape(x), dtype=object)
    out[...] = x
    return out


def _operand(x) -> tuple[np.ndarray, bool]:
    """(elements, batched) of a traced array, a numpy array or a Python or numpy number."""
    if isinstance(x, Traced):
        return x._e, x._batched
    if isinstance(x, (bool, int, float, np.integer, np.floating, np.bool_)):
        return _objects(float(x)), False
    if isinstance(x, np.ndarray) and x.dtype.kind in "biuf":
        return _objects(x.astype(float)), False
    raise Untraceable(f"an operand of type {type(x).__name__} (a traced residual takes numpy constants and numbers)")


def _align(ex: np.ndarray, bx: bool, ey: np.ndarray, by: bool) -> tuple[np.ndarray, np.ndarray, bool]:
    """Two operands' elements broadcast as numpy broadcasts (B, ...) arrays, the batch axis kept first: a batched
    operand must have the result's full rank, and an unbatched one of that rank a leading axis of 1 (dropped)."""
    if not (bx or by):
        return ex, ey, False
    rank = max(ex.ndim + bx, ey.ndim + by)
    out = []
    for e, b in ((ex, bx), (ey, by)):
        if b and e.ndim + 1 != rank:
            raise Untraceable("broadcasting moves the batch axis")
        if not b and e.ndim == rank:
            if e.shape[0] != 1:
                raise Untraceable(f"a constant of {e.shape[0]} rows against the batch axis")
            e = e[0]
        out.append(e)
    return out[0], out[1], True


def _apply(f, *arrays) -> np.ndarray:
    """f on the elements of object arrays (or single elements) broadcast together, as an object array."""
    return _objects(np.frompyfunc(f, len(arrays), 1)(*(_objects(a) for a in arrays)))


class Traced:
    """A traced array: ``_e``, an object array of scalar nodes (and numbers), the shape after the batch axis;
    ``_batched``: it has a leading batch axis (``q``, ``y`` and what is computed from them), else it is a constant
    array like a numpy one. Shapes report the batch axis as 1 (``len(q)`` is 1): a constant made with that many
    rows broadcasts along the batch."""

    __array_ufunc__ = None  # numpy defers to the reflected operators
    __array_priority__ = 1000

    def __init__(self, elements: np.ndarray, batched: bool):
        self._e, self._batched = _objects(elements), batched

    # --- the protocols a residual meets
    def __array_namespace__(self, api_version=None):
        return namespace

    def traced_frame_pose(self, robot, frame):
        """:meth:`manifoldgen.robot.Robot.frame_pose` of this traced q: (position (B, 3), rotation (B, 3, 3))."""
        return self._graph.frame_pose(robot, frame, self)

    def traced_com(self, robot):
        """:meth:`manifoldgen.robot.Robot.com` of this traced q: (B, 3)."""
        return self._graph.com(robot, self)

    @property
    def _graph(self) -> _Graph:
        graph = _element_graph(self._e)
        if graph is None:
            raise Untraceable("kinematics of a constant")
        return graph

    def __array__(self, *args, **kwargs):
        raise Untraceable("a traced array turned into a numpy array (a numpy function or another robot method)")

    def __array_function__(self, func, types, args, kwargs):
        raise Untraceable(f"numpy's {func.__name__} called on a traced array (use the namespace array_namespace(q))")

    def __bool__(self):
        raise Untraceable("a Python branch or comparison on a traced value")

    def __float__(self):
        raise Untraceable("a traced value turned into a Python number")

    __int__ = __index__ = __complex__ = __float__

    def __iter__(self):
        raise Untraceable("iterating over a traced array")

    def __setitem__(self, key, value):
        raise Untraceable("writing into a traced array")

    def _compare(self, other):
        raise Untraceable("a comparison of traced values")

    __lt__ = __le__ = __gt__ = __ge__ = __eq__ = __ne__ = _compare
    __hash__ = None

    # --- shape
    @property
    def shape(self) -> tuple[int, ...]:
        return ((1,) if self._batched else ()) + self._e.shape

    @property
    def ndim(self) -> int:
        return self._e.ndim + self._batched

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    @property
    def dtype(self):
        return np.dtype(np.float64)

    @property
    def device(self) -> str:
        return "cpu"

    def __len__(self) -> int:
        return self.shape[0] if self.shape else 0

    def _axis(self, axis: int, extra: int = 0) -> int:
        """A full axis (negative counted from the end of ndim + extra) as an axis of ``_e``; not the batch axis."""
        rank = self.ndim + extra
        if not isinstance(axis, (int, np.integer)) or not -rank <= axis < rank:
            raise Untraceable(f"axis {axis!r} of a {rank}-dimensional array")
        axis = int(axis) % rank
        if self._batched:
            if axis == 0:
                raise Untraceable("an operation along the batch axis")
            axis -= 1
        return axis

    def _axes(self, axis) -> tuple[int, ...]:
        if axis is None:
            if self._batched:
                raise Untraceable("a reduction over every axis, the batch axis included")
            return tuple(range(self._e.ndim))
        return tuple(self._axis(a) for a in (axis if isinstance(axis, (tuple, list)) else (axis,)))

    # --- arithmetic
    def _binary(self, op: str, other, reflected: bool = False) -> Traced:
        x, bx = self._e, self._batched
        y, by = _operand(other)
        if reflected:
            (x, bx), (y, by) = (y, by), (x, bx)
        x, y, batched = _align(x, bx, y, by)
        graph = _element_graph(x) or _element_graph(y)
        if graph is None:  # constants only
            return Traced(_apply(lambda a, b: _fold(BINARY[op], float(a), float(b)), x, y), batched)
        return Traced(_apply(lambda a, b: graph.binary(op, a, b), x, y), batched)

    def _unary(self, op: str) -> Traced:
        graph = _element_graph(self._e)
        if graph is None:
            return Traced(_apply(lambda a: _fold(UNARY[op], float(a)), self._e), self._batched)
        return Traced(_apply(lambda a: graph.unary(op, a), self._e), self._batched)

    def __add__(self, other):
        return self._binary("ADD", other)

    def __radd__(self, other):
        return self._binary("ADD", other, True)

    def __sub__(self, other):
        return self._binary("SUB", other)

    def __rsub__(self, other):
        return self._binary("SUB", other, True)

    def __mul__(self, other):
        return self._binary("MUL", other)

    def __rmul__(self, other):
        return self._binary("MUL", other, True)

    def __truediv__(self, other):
        return self._binary("DIV", other)

    def __rtruediv__(self, other):
        return self._binary("DIV", other, True)

    def __pow__(self, other):
        return self._binary("POW", other)

    def __rpow__(self, other):
        return self._binary("POW", other, True)

    def __neg__(self):
        return self._unary("NEG")

    def __pos__(self):
        return self

    def __abs__(self):
        return self._unary("ABS")

    def __matmul__(self, other):
        return _matmul(self, other)

    def __rmatmul__(self, other):
        return _matmul(other, self)

    # --- indexing and shape changes
    def __getitem__(self, key) -> Traced:
        key = key if isinstance(key, tuple) else (key,)
        if any(isinstance(k, (Traced, _Node)) or (isinstance(k, np.ndarray) and k.dtype.kind == "b")
               or isinstance(k, (bool, np.bool_)) for k in key):
            raise Untraceable("indexing with traced values or masks")
        key = tuple(np.asarray(k, dtype=np.intp) if isinstance(k, (list, np.ndarray)) else k for k in key)
        if self._batched:
            if key and key[0] is Ellipsis:
                consumed = sum(1 for k in key[1:] if k is not None)
                if consumed > self._e.ndim:
                    raise Untraceable("indexing the batch axis")
            elif key and isinstance(key[0], slice) and key[0] == slice(None):
                key = key[1:]
            else:
                raise Untraceable("indexing the batch axis (only [:, ...] or [..., ...] keep it)")
            advanced = [i for i, k in enumerate(key) if isinstance(k, np.ndarray)]
            if advanced:
                placed = [i for i, k in enumerate(key) if isinstance(k, (np.ndarray, int, np.integer))]
                if placed != list(range(placed[0], placed[-1] + 1)):
                    raise Untraceable("separated integer-array indices (numpy would move the batch axis)")
        try:
            return Traced(self._e[key], self._batched)
        except IndexError as exc:
            raise Untraceable(f"index: {exc}") from exc

    @property
    def T(self) -> Traced:
        if self._batched and self._e.ndim:
            raise Untraceable(".T moves the batch axis (use .mT or matrix_transpose)")
        return Traced(self._e.T, self._batched)

    @property
    def mT(self) -> Traced:
        return namespace.matrix_transpose(self)

    def reshape(self, *shape) -> Traced:
        return namespace.reshape(self, shape[0] if len(shape) == 1 and isinstance(shape[0], (tuple, list)) else shape)

    def sum(self, axis=None, keepdims=False, dim=None, keepdim=False):
        return namespace.sum(self, axis=axis if dim is None else dim, keepdims=keepdims or keepdim)

    def mean(self, axis=None, keepdims=False, dim=None, keepdim=False):
        return namespace.mean(self, axis=axis if dim is None else dim, keepdims=keepdims or keepdim)

    def astype(self, dtype, copy=True):
        return namespace.astype(self, dtype)


def _matmul(x, y) -> Traced:
    """``x @ y`` with numpy's rules, the batch axis kept first and never contracted."""
    (ex, bx), (ey, by) = _operand(x), _operand(y)
    if bx and by:
        ok = ex.ndim == ey.ndim >= 2
    elif bx:
        ok = (ex.ndim == 1 and ey.ndim in (1, 2)) or (ex.ndim >= 2 and ey.ndim <= ex.ndim)
    elif by:
        ok = ey.ndim >= 2 and ex.ndim <= ey.ndim
    else:
        ok = True
    if not ok:
        raise Untraceable("a matrix product that contracts or moves the batch axis")
    try:
        out = np.matmul(ex, ey)
    except ValueError as exc:
        raise Untraceable(f"matmul: {exc}") from exc
    return Traced(_objects(out), bx or by)


def _traced(x) -> Traced:
    if isinstance(x, Traced):
        return x
    e, b = _operand(x)
    return Traced(e, b)


def _like(x: Traced, value: float) -> Traced:
    return Traced(_apply(lambda _: float(value), x._e), x._batched)


class _Linalg:
    def vector_norm(self, x, /, *, axis=None, keepdims=False, ord=2):
        if ord != 2:
            raise Untraceable(f"vector_norm of ord {ord!r} (only 2)")
        x = _traced(x)
        return namespace.sqrt(namespace.sum(x * x, axis=axis, keepdims=keepdims))

    def cross(self, x1, x2, /, *, axis=-1):
        x1, x2 = _traced(x1), _traced(x2)
        if x1.shape[axis] != 3 or x2.shape[axis] != 3:
            raise Untraceable("cross of vectors that are not 3-vectors")
        xp = namespace
        a = [xp.take_axis(x1, i, axis) for i in range(3)]
        b = [xp.take_axis(x2, i, axis) for i in range(3)]
        parts = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
        return xp.stack(parts, axis=axis)

    def matmul(self, x1, x2, /):
        return _matmul(x1, x2)

    def vecdot(self, x1, x2, /, *, axis=-1):
        return namespace.vecdot(x1, x2, axis=axis)

    def matrix_transpose(self, x, /):
        return namespace.matrix_transpose(x)

    def __getattr__(self, name):
        if name.startswith("__"):  # probes (hasattr) of special names
            raise AttributeError(name)
        raise Untraceable(f"linalg.{name} is not recorded by the tracer")


class _Namespace:
    """The array namespace of traced arrays (``array_namespace(q)`` of a traced ``q``): the array API functions
    the tracer records; numpy's for constants."""

    __name__ = __name__
    linalg = _Linalg()
    float64, float32, pi, e, inf = np.float64, np.float32, math.pi, math.e, math.inf

    def __getattr__(self, name):
        if name.startswith("__"):  # probes (hasattr) of special names
            raise AttributeError(name)
        raise Untraceable(f"{name} is not recorded by the tracer")

    # elementwise
    def _unary(op):
        def f(self, x, /):
            return _traced(x)._unary(op)
        return f

    sqrt, sin, cos, tan = _unary("SQRT"), _unary("SIN"), _unary("COS"), _unary("TAN")
    exp, log, abs, tanh = _unary("EXP"), _unary("LOG"), _unary("ABS"), _unary("TANH")
    asin = arcsin = _unary("ASIN")
    acos = arccos = _unary("ACOS")
    atan = arctan = _unary("ATAN")
    negative = _unary("NEG")

    def _binary(op):
        def f(self, x1, x2, /):
            return _traced(x1)._binary(op, x2)
        return f

    add, subtract, multiply, divide = _binary("ADD"), _binary("SUB"), _binary("MUL"), _binary("DIV")
    maximum, minimum = _binary("MAX"), _binary("MIN")
    pow = power = _binary("POW")
    atan2 = arctan2 = _binary("ATAN2")
    del _unary, _binary

    def positive(self, x, /):
        return _traced(x)

    def square(self, x, /):
        x = _traced(x)
        return x * x

    def clip(self, x, /, min=None, max=None):
        x = _traced(x)
        x = x if min is None else self.maximum(x, min)
        return x if max is None else self.minimum(x, max)

    # reductions
    def _reduce(self, x, axis, keepdims, op):
        x = _traced(x)
        axes = x._axes(axis)
        e = x._e
        for a in sorted(axes, reverse=True):
            if e.shape[a] == 0:
                if op != "ADD":
                    raise Untraceable("a max, min or product over an empty axis")
                e = _objects(np.zeros(tuple(s for i, s in enumerate(e.shape) if i != a)))
                continue
            e = np.moveaxis(e, a, 0)
            out = e[0]
            for k in range(1, e.shape[0]):
                out = _apply(lambda u, v: _combine(op, u, v), out, e[k])
            e = out
        if keepdims:
            for a in sorted(axes):
                e = np.expand_dims(e, a)
        return Traced(_objects(e), x._batched)

    def sum(self, x, /, *, axis=None, dtype=None, keepdims=False):
        return self._reduce(x, axis, keepdims, "ADD")

    def prod(self, x, /, *, axis=None, dtype=None, keepdims=False):
        return self._reduce(x, axis, keepdims, "MUL")

    def max(self, x, /, *, axis=None, keepdims=False):
        return self._reduce(x, axis, keepdims, "MAX")

    def min(self, x, /, *, axis=None, keepdims=False):
        return self._reduce(x, axis, keepdims, "MIN")

    def mean(self, x, /, *, axis=None, keepdims=False):
        x = _traced(x)
        count = int(np.prod([x._e.shape[a] for a in x._axes(axis)]))
        return self.sum(x, axis=axis, keepdims=keepdims) / count

    def vecdot(self, x1, x2, /, *, axis=-1):
        product = _traced(x1) * x2
        return self.sum(product, axis=axis)

    def matmul(self, x1, x2, /):
        return _matmul(x1, x2)

    # joining and shapes
    def _joined(self, arrays, axis, new: bool):
        arrays = [_traced(a) for a in arrays]
        if not any(a._batched for a in arrays):
            join = np.stack if new else np.concatenate
            return Traced(_objects(join([a._e for a in arrays], axis=axis)), False)
        parts = []
        for a in arrays:
            if not a._batched:  # a constant with the batch axis as 1
                if a._e.ndim == 0 or a._e.shape[0] != 1:
                    raise Untraceable("joining traced arrays with a constant that has no batch axis of 1")
                a = Traced(a._e[0], True)
            parts.append(a)
        rank = parts[0].ndim
        if any(a.ndim != rank for a in parts):
            raise Untraceable("joining arrays of different ranks")
        axis = parts[0]._axis(axis, extra=int(new))
        join = np.stack if new else np.concatenate
        try:
            return Traced(_objects(join([a._e for a in parts], axis=axis)), True)
        except ValueError as exc:
            raise Untraceable(f"join: {exc}") from exc

    def concat(self, arrays, /, *, axis=0):
        return self._joined(arrays, axis, False)

    concatenate = concat

    def stack(self, arrays, /, *, axis=0):
        return self._joined(arrays, axis, True)

    def reshape(self, x, /, shape, *, copy=None):
        x = _traced(x)
        shape = tuple(int(s) for s in shape)
        if x._batched:
            if not shape or shape[0] not in (-1, 1):
                raise Untraceable(f"reshape to {shape} changes the batch axis")
            shape = shape[1:]
        try:
            return Traced(x._e.reshape(shape), x._batched)
        except ValueError as exc:
            raise Untraceable(f"reshape: {exc}") from exc

    def expand_dims(self, x, /, *, axis=0):
        x = _traced(x)
        return Traced(np.expand_dims(x._e, x._axis(axis, extra=1)), x._batched)

    def squeeze(self, x, /, axis):
        x = _traced(x)
        axes = x._axes(axis)
        if any(x._e.shape[a] != 1 for a in axes):
            raise Untraceable("squeeze of an axis longer than 1")
        return Traced(np.squeeze(x._e, axis=axes), x._batched)

    def permute_dims(self, x, /, axes):
        x = _traced(x)
        if len(axes) != x.ndim:
            raise Untraceable(f"permute_dims with {len(axes)} axes of a {x.ndim}-dimensional array")
        axes = [int(a) % x.ndim for a in axes]
        if x._batched:
            if axes[0] != 0:
                raise Untraceable("permute_dims moves the batch axis")
            axes = [a - 1 for a in axes[1:]]
        return Traced(np.transpose(x._e, axes), x._batched)

    def matrix_transpose(self, x, /):
        x = _traced(x)
        if x._e.ndim < 2:
            raise Untraceable("a matrix transpose of an array with fewer than two axes after the batch axis")
        return Traced(np.swapaxes(x._e, -1, -2), x._batched)

    def take_axis(self, x, index: int, axis: int):
        """x's entries ``index`` along ``axis`` (full axes), that axis dropped."""
        x = _traced(x)
        return Traced(np.take(x._e, index, axis=x._axis(axis)), x._batched)

    # constants
    def asarray(self, obj, /, *, dtype=None, device=None, copy=None):
        if isinstance(obj, Traced):
            return obj
        if isinstance(obj, (list, tuple)) and any(isinstance(v, Traced) for v in obj):
            raise Untraceable("asarray of a list of traced arrays (stack them)")
        return np.asarray(obj, dtype=float)

    def astype(self, x, dtype, /, *, copy=True):
        if isinstance(x, Traced):
            if np.dtype(dtype).kind != "f":
                raise Untraceable(f"a traced array cast to {dtype}")
            return x
        return np.asarray(x).astype(dtype)

    def zeros(self, shape, *, dtype=None, device=None):
        return np.zeros(shape)

    def ones(self, shape, *, dtype=None, device=None):
        return np.ones(shape)

    def full(self, shape, fill_value, *, dtype=None, device=None):
        return np.full(shape, float(fill_value))

    def eye(self, n_rows, n_cols=None, /, *, k=0, dtype=None, device=None):
        return np.eye(n_rows, n_cols, k=k)

    def zeros_like(self, x, /, *, dtype=None, device=None):
        return _like(x, 0.0) if isinstance(x, Traced) else np.zeros_like(x, dtype=float)

    def ones_like(self, x, /, *, dtype=None, device=None):
        return _like(x, 1.0) if isinstance(x, Traced) else np.ones_like(x, dtype=float)

    def full_like(self, x, /, fill_value, *, dtype=None, device=None):
        return _like(x, fill_value) if isinstance(x, Traced) else np.full_like(x, float(fill_value), dtype=float)


def _combine(op: str, u, v):
    if isinstance(u, _Node):
        return u.graph.binary(op, u, v)
    if isinstance(v, _Node):
        return v.graph.binary(op, u, v)
    return float(BINARY[op](float(u), float(v)))


namespace = _Namespace()


def batch(q: Traced, y, n: int, k: int) -> tuple[Traced, Traced]:
    """:meth:`~manifoldgen.constraints.Constraint.batch` of a traced ``q``: ``q`` as it is (B, n), ``y`` as (B, k)
    (a numpy ``y`` of k values, or (1, k), becomes constants along the batch)."""
    if not (q._batched and q._e.shape == (n,)):
        raise Untraceable(f"batch of a traced q of shape {q.shape}, not (B, {n})")
    if isinstance(y, Traced):
        if not (y._batched and y._e.shape == (k,)):
            raise Untraceable(f"batch of a traced y of shape {y.shape}, not (B, {k})")
        return q, y
    y = np.asarray(y, dtype=float)
    if y.size != k:
        raise Untraceable(f"batch of a y of shape {y.shape}, not (B, {k})")
    return q, Traced(_objects(y.reshape(k)), True)


def _outputs(value, rows: int | None, what: str) -> list[_Node]:
    """The scalar nodes of a traced (B, rows) result (a constant (1, rows) one too)."""
    e, batched = _operand(value)
    if not batched:
        if e.ndim != 2 or e.shape[0] != 1:
            raise Untraceable(f"the {what} is a constant of shape {e.shape}, not (1, m)")
        e = e[0]
    if e.ndim != 1 or (rows is not None and len(e) != rows):
        raise Untraceable(f"the {what} has shape (B, {', '.join(map(str, e.shape))}), not (B, {rows})")
    return list(e)


def trace(constraint, y: np.ndarray, robot) -> tuple[Program, Program]:
    """(residual, inequality) programs of ``constraint`` at the condition ``y (k,)`` on ``robot`` (the robot its
    ``frame_pose``/``com`` calls must name); raises :class:`Untraceable` with the reason when the residual uses
    something not recorded (its own exceptions, while traced, too)."""
    graph = _Graph(robot)
    graph.q = _objects([graph.leaf("Q", j) for j in range(robot.n)])
    q = Traced(graph.q, True)
    y = Traced(_objects(np.asarray(y, dtype=float).reshape(-1)), True)
    try:
        F = _outputs(constraint.residual(q, y), constraint.m, "residual")
        G = _outputs(constraint.inequality(q, y), None, "inequality")
    except Untraceable:
        raise
    except Exception as exc:  # the residual's own failure on a traced array: it stays in Python
        raise Untraceable(f"{type(exc).__name__}: {exc}") from exc
    return graph.program([graph.node(x) for x in F]), graph.program([graph.node(x) for x in G])
