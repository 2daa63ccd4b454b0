"""The compiled planning core (``manifoldgen_core``, C++ in ``native/``) behind the Python interfaces.

:func:`core_space` builds a ``manifoldgen_core.Space`` from a
:class:`~manifoldgen.space.ConstrainedSpace`: the robot model and the collision model (robot
geometries, obstacles, a held tool, the exact collision pairs) go over by pinocchio's own binary
serialization (:func:`write_models`, shared with the C++ OMPL baseline), the constraint as terms with
the condition ``y`` baked in: ``pose``, ``rotation`` (a pose term without position axes, its target
turned by ``y``), ``closed_chain``, ``sphere``, and the whole-body ones: ``balance`` (its feet and base height as
pose terms, its CoM margin as the support polygon's inequalities on pinocchio's centre of mass), ``orientation``
(two rows and its hemisphere inequality), ``joint_linear``, and sets of them, on fixed or floating bases (the
base's six Euler coordinates mapped to pinocchio's free flyer as :meth:`~manifoldgen.robot.Robot.to_pinocchio`
does). Any other constraint (a user's, ``plane``, ...) is traced once (:mod:`manifoldgen.constraints.trace`) into
compiled expressions, its residual and its inequalities, that the core evaluates per state with forward-mode
derivatives, no Python call per state (:func:`compiled_part`; checked against the numpy residual and central
differences on :data:`COMPILE_ROWS` random configurations before use). A constraint whose residual does not trace,
or whose compiled form disagrees, reaches the core through batched Python callbacks (:class:`ConstraintCallback`):
its own residual, Jacobian (analytic, else central differences of its numpy residual: torch autograd's within
~1e-9, and ~14x cheaper on the single rows the sequential searches ask for) and inequalities, called on all the
rows a projection iteration, a motion check or a path chunk evaluates at once; :func:`compile_report` says which
parts run compiled and why the others do not.
What the core cannot take (a robot that is not a pinocchio :class:`~manifoldgen.robot.Robot`): :func:`unsupported`
says why, and the planners fall back to Python.

The core applies :class:`~manifoldgen.space.ConstrainedSpace`'s rule in the same order (limits,
equality within ``limit`` x tolerance, inequalities, collision), lazily per state (with callbacks: the
tests before collision for a whole batch at once, as the Python space does, then collisions in order);
projection is :func:`~manifoldgen.constraints.project`'s algorithm with its options;
``tests/test_native.py``, ``tests/test_native_balance.py`` and ``tests/test_native_callback.py`` compare both
with the Python reference, ``tests/test_native_bad_inputs.py`` their refusals. The core's search
(:class:`~manifoldgen.planning.rrt_connect.CoreRRTConnect`) gives a sampler the core's ``valid``, ``violation``
and ``project`` through :class:`NativeSpace`, and books the core's operation counts on the planner's space
(:func:`book`), so results carry the same counters as a Python search.

Sphere models (:func:`set_spheres`): conservative spheres per robot geometry; when set, the searches
check robot-vs-primitive and robot-robot pairs with them (exact coal for the pairs they do not
cover), and every candidate path's final dense check stays exact.
"""

from __future__ import annotations

import tempfile
import warnings
import weakref
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from manifoldgen.constraints import Constraint, ConstraintSet, Projection
from manifoldgen.constraint_callbacks import FD_AGREE, ConstraintCallback, central_difference
from manifoldgen.constraints import projection, trace
from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot, as_batch
from manifoldgen.space import REASONS, ConstrainedSpace, PathReport, densify, malformed_path

CORES = ("auto", "python", "native")
BUILD_HINT = "install manifoldgen with pip, which compiles it (pip install -e . in a checkout: scripts/setup.sh does)"
# against the installed pin, without the isolated build's pinned one (the build tools must then be installed)
REBUILD = ("pip install scikit-build-core nanobind cmeel-eigen && pip install --no-build-isolation --no-deps "
           "--force-reinstall -e . (in the manifoldgen checkout)")
COUNTERS = ("evaluations", "jacobians", "projection_steps", "collision_checks")


def core_module():
    """The ``manifoldgen_core`` extension, or None when it is not built or does not fit the installed
    pinocchio (:func:`core_problem` says why)."""
    return None if core_problem() else _import_core()


def core_problem() -> str:
    """Why the compiled core cannot be used, with the command that fixes it, in one line; "" when it can. A core
    compiled against another pinocchio than the installed one is refused: its inline pinocchio code would not
    match the libraries it runs with."""
    try:
        core = _import_core()
    except ImportError as exc:  # the module is there but does not load (e.g. an undefined pinocchio symbol)
        return (f"the compiled core manifoldgen_core does not load with pinocchio {pin.__version__} "
                f"({(str(exc).splitlines() or [type(exc).__name__])[0]}); rebuild it: {REBUILD}")
    if core is None:
        return f"the compiled core manifoldgen_core is not installed; {BUILD_HINT}"
    if core.PINOCCHIO_VERSION != pin.__version__:
        return (f"the compiled core was built against pinocchio {core.PINOCCHIO_VERSION} but pinocchio "
                f"{pin.__version__} is installed; pip install pin=={core.PINOCCHIO_VERSION}, or rebuild the core "
                f"against {pin.__version__}: {REBUILD}")
    return ""


def _import_core():
    """The ``manifoldgen_core`` module; None when it is not installed."""
    try:
        import manifoldgen_core
    except ModuleNotFoundError as exc:
        if exc.name != "manifoldgen_core":
            raise
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
    """(idx_q, idx_v, nq) of each planning-group joint in pinocchio's q and v (nq 2: continuous); a floating
    base first, as its free flyer (nq 7), which stands for the group's six base coordinates."""
    joints = ([1] if robot.floating_base else []) + list(robot._joint_ids)
    return [(robot.model.joints[j].idx_q, robot.model.joints[j].idx_v, robot.model.joints[j].nq) for j in joints]


def _parts(space: ConstrainedSpace) -> list:
    constraint = space.constraint
    return constraint.parts if isinstance(constraint, ConstraintSet) else [constraint]


def unsupported(space: ConstrainedSpace) -> str | None:
    """Why the core cannot take ``space`` (a one-line reason), or None when it can."""
    if not isinstance(space.robot, Robot):
        return "the compiled core needs a pinocchio Robot"
    return None


# Compiled expressions of Python parts (constraints/trace.py, native/src/expression.cpp).
COMPILE_ROWS = 8  # random configurations a compiled part is checked on before use
COMPILE_AGREE = 1e-9  # its residual and inequalities against the numpy ones: within this x max(1, max |F|)


@dataclass(frozen=True)
class CompiledPart:
    """A Python constraint part at its condition y, traced: its residual and inequality programs."""

    residual: trace.Program
    inequality: trace.Program


_REPORTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # space -> its latest core's compile report


def compiled_part(part: Constraint, y: np.ndarray, robot: Robot) -> CompiledPart | str:
    """``part`` at the condition ``y (k,)`` traced into programs the core runs, or why not (a one-line reason:
    something its residual uses that the tracer does not record, or an operation the core lacks). Traced anew for
    every core (about a millisecond): a constraint changed since is traced as it is now."""
    try:
        residual, inequality = trace.trace(part, y, robot)
    except trace.Untraceable as exc:
        return f"its residual does not trace: {exc}"
    missing = {op for op, _, _ in residual.code + inequality.code} - set(core_module().Op.__members__)
    return f"the core has no operation {', '.join(sorted(missing))}" if missing else CompiledPart(residual, inequality)


def compile_report(space: ConstrainedSpace) -> dict:
    """What the latest :func:`core_space` of ``space`` compiled: ``compiled`` (the Python parts' types that run
    as compiled expressions) and ``callbacks`` (type -> why it runs through Python callbacks instead)."""
    return _REPORTS.get(space, {"compiled": [], "callbacks": {}})


def constraint_terms(space: ConstrainedSpace) -> list[dict]:
    """``space``'s constraint at its condition as the C++ terms (JSON-ready), in residual order:
    ``pose`` (frame_id, row-major rotation, position_axes, orientation_axes, y), ``chain`` (frame_a_id,
    frame_b_id, rotation, offset = d x axis) and ``sphere`` (frame_id, center, radius); a rotation
    constraint is a pose term without position axes, its target turned by y; ``orientation`` (frame_id, axis,
    basis (2, 3) rows) with its ``hemisphere`` inequality (frame_id, axis, direction), ``linear`` (A (r, n), y),
    a balance constraint as pose terms and a ``com_polygon`` inequality (normals (H, 2), bounds (H,)); a Python
    part that compiles as ``expression`` (code [[Op value, a, b]], constants, frames, outputs), its inequalities
    as ``expression_inequality``. Inequality terms add no residual rows. The compiled core and the C++ OMPL
    baseline both build from these; a part that neither is built in nor compiles is refused (one line)."""
    terms = []
    layout, refused = checked_layout(space, compile=True)
    for kind, item in layout:
        if kind == "callback":
            part = item.parts[0][0]
            raise ManifoldgenError(f"the compiled core has no '{part.spec()['type']}' constraint term (built in: "
                                   "pose, rotation, closed_chain, sphere, balance, orientation, joint_linear) and it "
                                   f"does not compile ({refused[id(part)]}); such a constraint reaches the core "
                                   "through Python callbacks only")
        if kind == "expression":
            compiled = item[2]
            terms.append({"type": "expression", **_program_json(compiled.residual)})
            if compiled.inequality.rows:
                terms.append({"type": "expression_inequality", **_program_json(compiled.inequality)})
            continue
        terms.append(item)
    return terms


def _program_json(program: trace.Program) -> dict:
    """A compiled program as the C++ OMPL baseline reads it: the core's ``Op`` values in place of their names."""
    op = core_module().Op
    return {"code": [[getattr(op, name).value, a, b] for name, a, b in program.code],
            "constants": list(program.constants), "frames": list(program.frames), "outputs": list(program.outputs)}


def _layout(space: ConstrainedSpace, compile: bool = True, refused: dict | None = None) -> list[tuple[str, object]]:
    """``space``'s constraint in residual order: ("term", a built-in part's C++ term, see
    :func:`constraint_terms`), ("expression", (part, y, its :class:`CompiledPart`)) for a part that is not built in
    and compiles (``compile``, and not in ``refused``: id(part) -> why not, to which it adds the parts that do not
    trace) and ("callback", a :class:`ConstraintCallback` for a run of consecutive parts that are not built in and
    do not)."""
    robot, out, offset = space.robot, [], 0
    refused = {} if refused is None else refused
    for part in _parts(space):
        y = space.y[offset:offset + part.condition.k]
        offset += part.condition.k
        terms = part.core_terms(y)
        if terms is not None:
            out += [("term", term) for term in terms]
            continue
        if compile and id(part) not in refused:
            compiled = compiled_part(part, y, robot)
            if isinstance(compiled, CompiledPart):
                out.append(("expression", (part, y, compiled)))
                continue
            refused[id(part)] = compiled
        if out and out[-1][0] == "callback":
            out[-1][1].parts.append((part, y))
        else:
            out.append(("callback", ConstraintCallback([(part, y)])))
    return out


def _python_inequalities(space: ConstrainedSpace, layout: list[tuple[str, object]]):
    """(p, G) for the parts of ``layout``'s callbacks that have inequalities: G(q (B, n)) -> (B, p) as the core
    calls it; None when there are none (the built-in and compiled inequalities run in C++)."""
    parts = [(part, y) for kind, item in layout if kind == "callback" for part, y in item.parts
             if part.inequality(space.robot.lower[None], y[None]).shape[1]]
    if not parts:
        return None

    def inequalities(q: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(np.concatenate(
            [part.inequality(q, np.broadcast_to(y, (len(q), len(y)))) for part, y in parts], axis=1), dtype=float)
    return inequalities(space.robot.lower[None]).shape[1], inequalities


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
    out = _build_core(space, layout)
    _REPORTS[space] = {"compiled": [term[0].spec()["type"] for kind, term in layout if kind == "expression"],
                       "callbacks": {part.spec()["type"]: refused.get(id(part), "compilation is off")
                                     for kind, term in layout if kind == "callback" for part, _ in term.parts}}
    return out


def checked_layout(space: ConstrainedSpace, compile: bool) -> tuple[list[tuple[str, object]], dict[int, str]]:
    """:func:`_layout` with the compiled parts that fail :func:`_disagreements`' check moved to callbacks (each
    with a warning), and ``refused``: id(part) -> why it is not compiled."""
    refused: dict[int, str] = {}
    layout = _layout(space, compile=compile, refused=refused)
    failed = _disagreements(space, [term for kind, term in layout if kind == "expression"])
    if failed:
        for part, why in failed:
            refused[id(part)] = why
            warnings.warn(f"constraint '{part.spec()['type']}': {why}; it runs through Python callbacks instead",
                          stacklevel=3)
        layout = _layout(space, compile=compile, refused=refused)
    return layout, refused


def _empty_core(space: ConstrainedSpace, geometry: bool = True):
    """A ``manifoldgen_core.Space`` of ``space``'s robot, limits and settings without constraint terms; with its
    collision model (``geometry``), else with none."""
    robot = space.robot
    with tempfile.TemporaryDirectory(prefix="manifoldgen-core-") as folder:
        if geometry:
            model_file, geometry_file = write_models(space, Path(folder))
        else:
            model_file, geometry_file = Path(folder) / "model.bin", Path(folder) / "geometry.bin"
            robot.model.saveToBinary(str(model_file))
            pin.GeometryModel().saveToBinary(str(geometry_file))
        return core_module().Space(str(model_file), str(geometry_file), robot.reference, active_coordinates(robot),
                                   robot.lower, robot.upper, space.settings.margin, space.settings.resolution)


def _build_core(space: ConstrainedSpace, layout: list[tuple[str, object]]):
    """The core for ``space`` with the constraint as ``layout`` has it (:func:`_layout`)."""
    out = _empty_core(space)
    for kind, term in layout:
        if kind == "callback":
            out.add_callback(term.rows, term.residuals)
            continue
        if kind == "expression":
            _add_compiled(out, term[2])
            continue
        kind = term["type"]
        if kind == "pose":
            out.add_pose(term["frame_id"], np.reshape(term["rotation"], (3, 3)), term["position_axes"],
                         term["orientation_axes"], np.asarray(term["y"], float))
        elif kind == "sphere":
            out.add_sphere(term["frame_id"], np.asarray(term["center"], float), term["radius"])
        elif kind in WHOLE_BODY:
            _add_whole_body(out, term)
        else:
            out.add_chain(term["frame_a_id"], term["frame_b_id"], np.reshape(term["rotation"], (3, 3)),
                          np.asarray(term["offset"], float))
    out.set_tolerance(np.asarray(space.constraint.tolerance, float))
    python_inequalities = _python_inequalities(space, layout)
    if python_inequalities:
        out.set_inequalities(*python_inequalities)
    return out


def _add_compiled(core, compiled: CompiledPart) -> tuple[slice, slice]:
    """Add a compiled part's residual and inequalities to ``core``: their rows (slices of its residual and of its
    inequality)."""
    m, g = core.m, core.g
    core.add_expression(*_lowered(compiled.residual))
    if compiled.inequality.rows:
        core.add_expression_inequality(*_lowered(compiled.inequality))
    return slice(m, core.m), slice(g, core.g)


def _lowered(program: trace.Program) -> tuple:
    """A program as ``add_expression`` takes it: code with the core's ``Op`` codes, constants, frames, outputs."""
    op = core_module().Op
    return ([(getattr(op, name), a, b) for name, a, b in program.code], list(program.constants),
            list(program.frames), list(program.outputs))


def _disagreements(space: ConstrainedSpace, compiled: list[tuple]) -> list[tuple[Constraint, str]]:
    """The compiled parts ((part, y, :class:`CompiledPart`)) whose residual, inequalities or Jacobian, in a core of
    their own, differ from the part's own on :data:`COMPILE_ROWS` random configurations, and why. Residual and
    inequalities: the numpy ones within :data:`COMPILE_AGREE`; the Jacobian: :func:`central_difference` of the
    numpy residual within :data:`FD_AGREE`, else the part's ``jacobian`` (autograd unless it has its own: central
    differences cross the kinks of a non-smooth residual) within :data:`COMPILE_AGREE`; each relative to
    max(1, max |.|). A part whose own evaluation raises there is left to Python too."""
    if not compiled:
        return []
    core = _empty_core(space, geometry=False)
    rows = [_add_compiled(core, c) for _, _, c in compiled]
    q = space.robot.sample_uniform(COMPILE_ROWS, np.random.default_rng(0))
    F, J = core.jacobian(q)
    G = core.inequality(q)
    failed = []
    for (part, y, _), (residual_rows, inequality_rows) in zip(compiled, rows):
        ys = np.broadcast_to(y, (len(q), len(y)))
        try:
            what, error = "residual", _error(F[:, residual_rows], part.residual(q, ys), COMPILE_AGREE)
            if error is None:
                what, error = "inequality", _error(G[:, inequality_rows], part.inequality(q, ys), COMPILE_AGREE)
            ours = J[:, residual_rows]
            if error is None and _error(ours, central_difference(part.residual, q, ys)[1], FD_AGREE) is not None:
                what, error = "Jacobian", _error(ours, part.jacobian(q, ys)[1], COMPILE_AGREE)
        except Exception as exc:  # the part's own evaluation refuses a random configuration: left to Python
            failed.append((part, f"its numpy residual raised on random configurations ({type(exc).__name__}: {exc})"))
            continue
        if error is not None:
            failed.append((part, f"its compiled {what} differs from its numpy {what} by {error:.1e} on random "
                                 "configurations"))
    return failed


def _error(ours: np.ndarray, theirs, agree: float) -> float | None:
    """max |ours - theirs| when it exceeds ``agree`` x max(1, max |theirs|), else None."""
    theirs = np.asarray(theirs, dtype=float)
    error = _difference(ours, theirs)
    return error if error > agree * max(1.0, float(np.max(np.abs(np.nan_to_num(theirs)), initial=0.0))) else None


def _difference(a: np.ndarray, b: np.ndarray) -> float:
    """max |a - b|, NaN where both are NaN counting as equal (inf where only one is, or the shapes differ)."""
    if a.shape != b.shape:
        return np.inf
    both = np.isnan(a) & np.isnan(b)
    d = np.where(both, 0.0, np.abs(a - b))
    return float(np.max(np.nan_to_num(d, nan=np.inf), initial=0.0))


WHOLE_BODY = ("orientation", "linear", "com_polygon", "hemisphere")


def _add_whole_body(core, term: dict) -> None:
    """Add a whole-body term of :func:`constraint_terms` to ``core``."""
    kind = term["type"]
    if kind == "orientation":
        core.add_orientation(term["frame_id"], np.asarray(term["axis"], float), np.asarray(term["basis"], float))
    elif kind == "linear":
        core.add_linear(np.ascontiguousarray(term["A"], float), np.asarray(term["y"], float))
    elif kind == "com_polygon":
        core.add_com_polygon(np.ascontiguousarray(term["normals"], float), np.asarray(term["bounds"], float))
    else:
        core.add_hemisphere(term["frame_id"], np.asarray(term["axis"], float), np.asarray(term["direction"], float))


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
    """``space`` with the core's ``project`` and ``valid`` (the same rule and results; 3-7x faster on a batch)
    when the core is built and takes every part of its constraint without Python callbacks, else ``space``
    itself. Built once per space."""
    if space not in _FAST:
        fast = space
        if not core_problem() and not unsupported(space):
            core = core_space(space)
            if not compile_report(space)["callbacks"]:
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
