"""The compiled planning core (``manifoldgen_core``, C++ in ``native/``) behind the Python interfaces.

:func:`core_space` builds a ``manifoldgen_core.Space`` from a
:class:`~manifoldgen.space.ConstrainedSpace`: the robot model and the collision model (robot
geometries, obstacles, a held tool, the exact collision pairs) go over by pinocchio's own binary
serialization (:func:`write_models`, shared with the C++ OMPL baseline), the constraint as terms with
the condition ``y`` baked in: ``pose``, ``rotation`` (a pose term without position axes, its target
turned by ``y``), ``closed_chain``, ``sphere``, and sets of them, on fixed-base robots. Anything else (a user's
Python constraint, balance, a floating base) is not built in: :func:`unsupported` says why, and the
planners fall back to Python.

The core applies :class:`~manifoldgen.space.ConstrainedSpace`'s rule in the same order (limits,
equality within ``limit`` x tolerance, collision), lazily per state; projection is
:func:`~manifoldgen.constraints.project`'s algorithm with its options; ``tests/test_native.py``
compares both with the Python reference. :func:`plan_rrt_connect` runs
:class:`~manifoldgen.planning.RRTConnect`'s search in C++, the sampler feeding it through a callback
with its raw rows (:meth:`~manifoldgen.sampling.Sampler.raw_many`: lazy samples, :data:`LAZY_SAMPLES`):
the core refines and checks a row (limits, constraint) only when the search first uses it, and checks
its collisions as it checks every state it keeps, so most pooled rows cost a decode and nothing more.
:class:`NativeSpace` gives a sampler the core's ``valid``, ``violation`` and ``project`` during a native
search (for samplers fed eagerly, ``LAZY_SAMPLES = False``). The core's operation counts are booked on
the planner's space, so results carry the same counters as a Python search.

Sphere models (:func:`set_spheres`): conservative spheres per robot geometry; when set, the searches
check robot-vs-primitive and robot-robot pairs with them (exact coal for the pairs they do not
cover), and every candidate path's final dense check stays exact.
"""

from __future__ import annotations

import tempfile
import time
import warnings
import weakref
from pathlib import Path

import numpy as np
import pinocchio as pin

from manifoldgen.constraints import ConstraintSet, Projection
from manifoldgen.constraints.closed_chain import ClosedChainConstraint
from manifoldgen.constraints.pose import PoseConstraint
from manifoldgen.constraints.rotation import RotationConstraint
from manifoldgen.constraints.sphere import SphereConstraint
from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot
from manifoldgen.space import REASONS, ConstrainedSpace

CORES = ("auto", "python", "native")
BUILD_HINT = "build it with scripts/setup.sh (pip install --no-build-isolation ./native)"
COUNTERS = ("evaluations", "jacobians", "projection_steps", "collision_checks")
TARGET_BATCH = 32  # samples fetched per callback for the search's targets (the pool draws pool_batch)
# lazy edge checks (native/src/planner.cpp, Search::verify): measured wall 31 -> 28 ms, maze 107 -> 304 ms
# (the trees grow through the maze's walls), so off
LAZY = False
# lazy samples (planner.cpp): the sampler's raw rows go to the search, which refines and checks a row only
# when it first uses it
LAZY_SAMPLES = True


def core_module():
    """The ``manifoldgen_core`` extension, or None when it is not built."""
    try:
        import manifoldgen_core
    except ImportError:
        return None
    return manifoldgen_core


def write_models(space: ConstrainedSpace, folder: Path) -> tuple[Path, Path]:
    """Write the robot model and the space's collision model (obstacles and exact pairs included) with
    pinocchio's binary serialization into ``folder``: (model file, geometry file)."""
    folder = Path(folder)
    model_file, geometry_file = folder / "model.bin", folder / "geometry.bin"
    space.robot.model.saveToBinary(str(model_file))
    (space.checker.geom if space.checker is not None else pin.GeometryModel()).saveToBinary(str(geometry_file))
    return model_file, geometry_file


def active_coordinates(robot) -> list[tuple[int, int, int]]:
    """(idx_q, idx_v, nq) of each planning-group joint in pinocchio's q and v (nq 2: continuous)."""
    return [(robot.model.joints[j].idx_q, robot.model.joints[j].idx_v, robot.model.joints[j].nq)
            for j in robot._joint_ids]


def _parts(space: ConstrainedSpace) -> list:
    constraint = space.constraint
    return constraint.parts if isinstance(constraint, ConstraintSet) else [constraint]


BUILT_IN = (PoseConstraint, RotationConstraint, ClosedChainConstraint, SphereConstraint)


def unsupported(space: ConstrainedSpace) -> str | None:
    """Why the core cannot take ``space`` (a one-line reason), or None when it can."""
    for part in _parts(space):
        if type(part) not in BUILT_IN:
            return (f"the compiled core has no '{part.spec()['type']}' constraint (built in: pose, rotation, "
                    "closed_chain, sphere); a Python constraint runs in Python")
    if not isinstance(space.robot, Robot):
        return "the compiled core needs a pinocchio Robot"
    if space.robot.floating_base:
        return "the compiled core does not handle a floating base"
    return None


def constraint_terms(space: ConstrainedSpace) -> list[dict]:
    """``space``'s built-in constraint at its condition as the C++ terms (JSON-ready), in residual order:
    ``pose`` (frame_id, row-major rotation, position_axes, orientation_axes, y), ``chain`` (frame_a_id,
    frame_b_id, rotation, offset = d x axis) and ``sphere`` (frame_id, center, radius); a rotation
    constraint is a pose term without position axes, its target turned by y. The compiled core and the
    C++ OMPL baseline both build from these."""
    robot, terms, offset = space.robot, [], 0
    for part in _parts(space):
        y = space.y[offset:offset + part.condition.k]
        offset += part.condition.k
        if type(part) is PoseConstraint:
            terms.append({"type": "pose", "frame": part.frame, "frame_id": robot.frame_id(part.frame),
                          "rotation": part.rotation.reshape(-1).tolist(), "position_axes": list(part._idx),
                          "orientation_axes": list(part._oidx), "y": y.tolist()})
        elif type(part) is RotationConstraint:
            terms.append({"type": "pose", "frame": part.frame, "frame_id": robot.frame_id(part.frame),
                          "rotation": part.target(y[None])[0].reshape(-1).tolist(), "position_axes": [],
                          "orientation_axes": [0, 1, 2], "y": []})
        elif type(part) is SphereConstraint:
            terms.append({"type": "sphere", "frame": part.frame, "frame_id": robot.frame_id(part.frame),
                          "center": part.center.tolist(), "radius": float(y[0])})
        else:
            terms.append({"type": "chain", "frame_a": part.frame_a, "frame_b": part.frame_b,
                          "frame_a_id": robot.frame_id(part.frame_a), "frame_b_id": robot.frame_id(part.frame_b),
                          "rotation": part.rotation.reshape(-1).tolist(), "offset": (y[0] * part.axis).tolist()})
    return terms


def core_space(space: ConstrainedSpace):
    """A ``manifoldgen_core.Space`` for ``space`` (see the module docstring); a one-line error when the
    core is not built or cannot take the space."""
    core = core_module()
    if core is None:
        raise ManifoldgenError(f"the compiled core manifoldgen_core is not installed; {BUILD_HINT}")
    reason = unsupported(space)
    if reason:
        raise ManifoldgenError(f"{reason}; use core='python' or 'auto'")
    robot = space.robot
    with tempfile.TemporaryDirectory(prefix="manifoldgen-core-") as folder:
        model_file, geometry_file = write_models(space, Path(folder))
        out = core.Space(str(model_file), str(geometry_file), robot.reference, active_coordinates(robot),
                         robot.lower, robot.upper, space.settings.margin, space.settings.resolution)
    for term in constraint_terms(space):
        kind = term["type"]
        if kind == "pose":
            out.add_pose(term["frame_id"], np.reshape(term["rotation"], (3, 3)), term["position_axes"],
                         term["orientation_axes"], np.asarray(term["y"], float))
        elif kind == "sphere":
            out.add_sphere(term["frame_id"], np.asarray(term["center"], float), term["radius"])
        else:
            out.add_chain(term["frame_a_id"], term["frame_b_id"], np.reshape(term["rotation"], (3, 3)),
                          np.asarray(term["offset"], float))
    out.set_tolerance(np.asarray(space.constraint.tolerance, float))
    return out


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
    :func:`set_spheres` takes them; kept per collision checker."""
    checker = space.checker
    if checker not in _SPHERES:
        from manifoldgen.spheres import SphereChecker
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the pairs left to coal are listed in "exact"
            spheres = SphereChecker(checker)
        _SPHERES[checker] = {"joint": spheres.joint, "center": spheres.center, "radius": spheres.radius,
                             "geometry": spheres.geometry, "exact": list(spheres.exact_pairs)}
    return _SPHERES[checker]


def _rows(q: np.ndarray, n: int) -> np.ndarray:
    q = np.ascontiguousarray(q, dtype=float)
    return q.reshape(1, n) if q.ndim == 1 else q


class NativeSpace:
    """``space``'s rule on the compiled ``core``: what a sampler asks (``valid``, ``violation``,
    ``project``); everything else is ``space``'s. The core's counts are booked on ``space`` by whoever
    runs the search (:func:`plan_rrt_connect`), not here. ``collision=False``: :meth:`valid` leaves the
    collision test out (for a search that checks every state it keeps, samples included)."""

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

    def project(self, q: np.ndarray, *, tol: float = 1e-6, max_iters: int = 50, damping: float = 1e-6,
                max_step: float = 0.5) -> Projection:
        x, ok, iterations, residual = self._core.project(_rows(q, self._space.n), tol, max_iters, damping, max_step)
        return Projection(x, ok.astype(bool), iterations, residual)


def book(space: ConstrainedSpace, before: dict, after: dict) -> None:
    """Add the core's counts between ``before`` and ``after`` to ``space``'s counters."""
    for key in COUNTERS:
        setattr(space, key, getattr(space, key) + after[key] - before[key])
    for reason in REASONS:
        space.stopped[reason] += after["stopped"][reason] - before["stopped"][reason]


def _raw_draw(planner):
    """The search's callback for lazy samples: ``count`` -> (count, n) raw rows of the planner's sampler."""
    from manifoldgen.planning.base import SamplerFailed

    def draw(count: int) -> np.ndarray:
        planner.samples += count
        try:
            return planner.sampler.raw_many(count)
        except ManifoldgenError as exc:
            raise SamplerFailed(str(exc)) from exc
    return draw


def plan_rrt_connect(planner, core, start: np.ndarray, goal: np.ndarray, deadline: float) -> np.ndarray | None:
    """RRT-Connect in the core for ``planner`` (an :class:`~manifoldgen.planning.RRTConnect` whose
    settings and sampler it uses): the direct connection, then the search, until ``deadline``
    (``time.perf_counter`` seconds). With :data:`LAZY_SAMPLES` the sampler's raw rows go to the core,
    which refines (``sampler.lazy_refine`` iterations) and checks each when it first uses it. Books
    iterations, samples, rejections, projections, the sampler's refined and accepted rows and the core's
    operation counts on the planner; the path (K, n) that passed the exact dense check, or None."""
    s, space, sampler = planner.settings, planner.space, planner.sampler
    # a core built before lazy samples has no `refine` argument: it gets checked samples, as it expects
    lazy = LAZY_SAMPLES and hasattr(sampler, "raw_many") and "refine" in (core_module().rrt_connect.__doc__ or "")
    before = core.counts()
    swapped = sampler.space is space
    if swapped:  # the sampler's checks and refinement run in the core; collisions lazily, in the search
        sampler.space = NativeSpace(space, core, collision=False)
    try:
        out = core_module().rrt_connect(core, np.ascontiguousarray(start, float), np.ascontiguousarray(goal, float),
                               _raw_draw(planner) if lazy else planner._draw_many,
                               max(deadline - time.perf_counter(), 0.0), s.range, s.resolution, s.step, s.partial,
                               s.pool, s.pool_batch, s.candidates, planner.local.name, TARGET_BATCH, LAZY,
                               **({"refine": int(sampler.lazy_refine)} if lazy else {}))
    finally:
        if swapped:
            sampler.space = space
        after = core.counts()
        book(space, before, after)
        planner.sphere_checks = after["sphere_checks"] - before["sphere_checks"]
    planner.iterations += out["iterations"]
    planner.rejected += out["rejected_paths"]
    planner.out_of_reach += out["out_of_reach"]
    planner.local.projections += out["projections"]
    planner.native_nodes = list(out["nodes"])
    planner.cut_edges = out["cut_edges"]
    if lazy:
        sampler.stats.refined += out["refined"] if sampler.lazy_refine else 0
        sampler.stats.accepted += out["accepted"]
    return out["path"] if len(out["path"]) else None
