"""The compiled planning core (``manifoldgen_core``, C++ in ``native/``) behind the Python interfaces.

:func:`core_space` builds a ``manifoldgen_core.Space`` from a :class:`~manifoldgen.space.ConstrainedSpace`: an
empty core of its robot and collision model (:func:`~manifoldgen.core_extension.empty_core`) with its constraint
added as terms (:mod:`manifoldgen.core_terms`: built-in terms, compiled expressions, Python callbacks;
:func:`compile_report` says which parts run compiled and why the others do not).

The core applies :class:`~manifoldgen.space.ConstrainedSpace`'s rule in the same order (limits,
equality within ``limit`` x tolerance, inequalities, collision), lazily per state (with callbacks: the
tests before collision for a whole batch at once, as the Python space does, then collisions in order);
projection is :func:`~manifoldgen.constraints.project`'s algorithm with its options;
``tests/test_native.py``, ``tests/test_native_balance.py`` and ``tests/test_native_callback.py`` compare both
with the Python reference, ``tests/test_native_bad_inputs.py`` their refusals. :class:`NativeSpace` puts the
core's ``valid``, ``violation``, ``project`` and path checks behind the space's interface (:func:`fast_space`: the
one collection, the scene targets and a model sampler's projections use); a search in the core books its operation
counts on the planner's space (:func:`book`), so results carry the same counters as a Python search.

Sphere models (:func:`set_spheres`, :func:`space_spheres`): conservative spheres per robot geometry; when set, the
searches check robot-vs-primitive and robot-robot pairs with them (exact coal for the pairs they do not cover),
and every candidate path's final dense check stays exact.
"""

from __future__ import annotations

import warnings
import weakref

import numpy as np

from manifoldgen.constraints import Projection, projection
from manifoldgen.core_extension import core_problem, empty_core, unsupported
from manifoldgen.core_terms import add_terms, checked_layout
from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import as_batch
from manifoldgen.space import REASONS, ConstrainedSpace, PathReport, densify, malformed_path

COUNTERS = ("evaluations", "jacobians", "projection_steps", "collision_checks")


_REPORTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # space -> its latest core's compile report


def core_space(space: ConstrainedSpace, *, compile: bool = True):
    """A ``manifoldgen_core.Space`` for ``space`` (see the module docstring); a one-line error when the
    core is not built or cannot take the space. ``compile``: Python parts that trace and pass
    :func:`_disagreements`' check run as compiled expressions, the others (all of them without ``compile``)
    through callbacks (:func:`compile_report` says which did, and why not)."""
    problem = core_problem()
    if problem:
        raise ManifoldgenError(problem)
    reason = unsupported(space)
    if reason:
        raise ManifoldgenError(f"{reason}; use core='python' or 'auto'")
    layout, refused = checked_layout(space, compile)
    out = empty_core(space)
    add_terms(out, space, layout)
    out.prepare()  # what the first certified path check would build: here, not in a query's time
    _REPORTS[space] = {"compiled": [term[0].spec()["type"] for kind, term in layout if kind == "expression"],
                       "callbacks": {part.spec()["type"]: refused.get(id(part), "compilation is off")
                                     for kind, term in layout if kind == "callback" for part, _ in term.parts}}
    return out


def compile_report(space: ConstrainedSpace) -> dict:
    """What the latest :func:`core_space` of ``space`` compiled: ``compiled`` (the Python parts' types that run
    as compiled expressions) and ``callbacks`` (type -> why it runs through Python callbacks instead)."""
    return _REPORTS.get(space, {"compiled": [], "callbacks": {}})


def set_spheres(core, spheres: dict) -> str:
    """Give the core conservative sphere models: ``spheres`` holds ``joint (S,)`` pinocchio joint ids,
    ``center (S, 3)`` in that joint's frame, ``radius (S,)``, ``geometry (S,)`` the robot geometry each
    covers, and optionally ``exact``: geometry pairs ``(a, b)`` left to coal. Returns what the sphere
    check covers (sphere-sphere, sphere-primitive, exact pairs)."""
    try:
        core.set_spheres([int(j) for j in spheres["joint"]], np.ascontiguousarray(spheres["center"], float),
                         np.ascontiguousarray(spheres["radius"], float), [int(g) for g in spheres["geometry"]],
                         [(int(a), int(b)) for a, b in spheres.get("exact", ())])
    except (KeyError, RuntimeError, ValueError, TypeError) as exc:
        raise ManifoldgenError(f"bad sphere model: {exc}; give joint (S,), center (S, 3), radius (S,), "
                               "geometry (S,)") from exc
    return core.sphere_report()


_SPHERES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # CollisionChecker -> its sphere arrays


def space_spheres(space: ConstrainedSpace) -> dict:
    """The sphere models of ``space``'s robot and held object (:mod:`manifoldgen.spheres`, cached on disk)
    with the pairs they leave to coal (mesh obstacles, geometries without spheres, tight self pairs), as
    :func:`set_spheres` takes them, and ``fallback``: geometry name -> why it has no spheres (every pair
    it is in is checked exactly; said once in a one-line warning); kept per collision checker."""
    checker = space.checker
    if checker not in _SPHERES:
        from manifoldgen.spheres import SphereChecker
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the pairs left to coal are listed in "exact"
            spheres = SphereChecker(checker)
        if spheres.fallback:
            warnings.warn("sphere models: " + "; ".join(f"{name} has none ({why})" for name, why in
                                                        spheres.fallback.items())
                          + "; coal checks its pairs exactly", stacklevel=2)
        _SPHERES[checker] = {"joint": spheres.joint, "center": spheres.center, "radius": spheres.radius,
                             "geometry": spheres.geometry, "exact": list(spheres.exact_pairs),
                             "fallback": dict(spheres.fallback)}
    return _SPHERES[checker]


def _rows(q: np.ndarray, n: int) -> np.ndarray:
    """``q`` as (B, n) C-contiguous floats, refused as the Python space refuses it."""
    return np.ascontiguousarray(as_batch(q, n))


class NativeSpace:
    """``space``'s rule on the compiled ``core``: what a sampler asks (``valid``, ``violation``,
    ``project``), motion and path checks (``valid_prefix``, ``validate_path``, with the same refusals and
    reports as ``space``); everything else is ``space``'s. The core's counts are booked on ``space`` by whoever
    runs the search (:class:`~manifoldgen.planning.rrt_connect.CoreRRTConnect`), not here. ``collision=False``:
    :meth:`valid` leaves the collision test out (for a search that checks every state it keeps, samples
    included)."""

    def __init__(self, space: ConstrainedSpace, core, *, collision: bool = True):
        self._space, self._core, self._collision = space, core, collision

    def __getattr__(self, name):
        return getattr(self._space, name)

    def violation(self, q: np.ndarray) -> np.ndarray:
        return self._core.violation(_rows(q, self._space.n))

    def valid(self, q: np.ndarray, *, equality: bool = True) -> np.ndarray:
        q = _rows(q, self._space.n)
        limit = np.full(len(q), 1.0 if equality else np.inf)
        return self._core.codes(q, limit, self._collision, True) == 0

    def project(self, q: np.ndarray, *, tol: float = projection.TOL, max_iters: int = projection.MAX_ITERS,
                damping: float = projection.DAMPING, max_step: float = projection.MAX_STEP) -> Projection:
        x, ok, iterations, residual = self._core.project(_rows(q, self._space.n), tol, max_iters, damping, max_step)
        return Projection(x, ok.astype(bool), iterations, residual)

    def valid_prefix(self, states: np.ndarray, last_is_node: bool) -> int:
        """:meth:`ConstrainedSpace.valid_prefix` in the core (``stop`` set alike)."""
        count = self._core.valid_prefix(_rows(states, self._space.n), last_is_node)
        self.stop = REASONS[self._core.stop - 1] if self._core.stop else None
        return count

    def validate_path(self, path: np.ndarray) -> PathReport:
        """:meth:`ConstrainedSpace.validate_path` in the core: the same report (the first invalid state
        described by the Python space's :meth:`~ConstrainedSpace.problem`)."""
        resolution = self._space.settings.resolution
        path = np.asarray(path, dtype=float)
        why = malformed_path(path, self._space.n)
        if why:
            return PathReport(False, np.inf, why, resolution=resolution)
        valid, worst, first, _, segment, states = self._core.validate_path(np.ascontiguousarray(path))
        if valid:
            return PathReport(True, worst, "", -1, states, resolution)
        state = densify(path, resolution)[0][first]
        return PathReport(False, worst, f"segment {segment}: {self._space.problem(state)}", segment, states,
                          resolution)


_FAST: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # space -> its NativeSpace, or itself


def fast_space(space: ConstrainedSpace) -> ConstrainedSpace | NativeSpace:
    """``space`` with the core's ``project`` and ``valid`` (the same rule and results, collisions behind the sphere
    broad phase; 3-7x faster on a batch)
    when the core is built and takes every part of its constraint without Python callbacks, else ``space``
    itself. Built once per space."""
    if space not in _FAST:
        fast = space
        if not core_problem() and not unsupported(space):
            core = core_space(space)
            if not compile_report(space)["callbacks"]:
                if space.checker is not None:  # the sphere broad phase, as the planner's: the same verdicts
                    set_spheres(core, space_spheres(space))
                fast = NativeSpace(space, core)
        _FAST[space] = fast
    return _FAST[space]


def book(space: ConstrainedSpace, before: dict, after: dict) -> None:
    """Add the core's counts between ``before`` and ``after`` to ``space``'s counters."""
    for key in COUNTERS:
        setattr(space, key, getattr(space, key) + after[key] - before[key])
    for reason in REASONS:
        space.stopped[reason] += after["stopped"][reason] - before["stopped"][reason]


def valid_query_state(space: ConstrainedSpace, core, q: np.ndarray) -> np.ndarray | None:
    """A start or goal ``q (n,)`` as floats when the core finds it valid (limits, constraint, inequalities,
    exact collisions; its counts booked on ``space``), else None: the space's own check then says what is wrong."""
    q = np.asarray(q, dtype=float)
    if q.shape != (space.n,) or not np.all(np.isfinite(q)):
        return None
    before = core.counts()
    valid = core.codes(q[None], np.ones(1), True, True)[0] == 0
    book(space, before, core.counts())
    return q if valid else None
