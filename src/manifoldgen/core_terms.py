"""A constraint as the compiled core's terms, in residual order (:func:`layout`, :func:`add_terms`).

A built-in part gives its own C++ terms with the condition ``y`` baked in (``Constraint.core_terms``): ``pose``,
``rotation`` (a pose term without position axes, its target turned by ``y``), ``closed_chain``, ``sphere``, and
the whole-body ones: ``balance`` (its feet and base height as pose terms, its CoM margin as the support polygon's
inequalities on pinocchio's centre of mass), ``orientation`` (two rows and its hemisphere inequality),
``joint_linear``. Any other part (a user's, ``plane``, ...) is traced once (:mod:`manifoldgen.constraints.trace`)
into compiled expressions, its residual and its inequalities, that the core evaluates per state with forward-mode
derivatives, no Python call per state (:func:`compiled_part`; checked against the numpy residual and central
differences on :data:`COMPILE_ROWS` random configurations before use, :func:`checked_layout`). A part whose
residual does not trace, or whose compiled form disagrees, reaches the core through batched Python callbacks
(:class:`~manifoldgen.constraint_callbacks.ConstraintCallback`): its own residual, Jacobian (analytic, else central
differences of its numpy residual: torch autograd's within ~1e-9, and ~14x cheaper on the single rows the
sequential searches ask for) and inequalities, called on all the rows a projection iteration, a motion check or a
path chunk evaluates at once. :func:`constraint_terms` gives the same layout as JSON-ready terms for the C++ OMPL
baseline.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from manifoldgen.constraint_callbacks import FD_AGREE, ConstraintCallback, central_difference
from manifoldgen.constraints import Constraint, ConstraintSet, trace
from manifoldgen.core_extension import core_module, empty_core
from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot
from manifoldgen.space import ConstrainedSpace

COMPILE_ROWS = 8  # random configurations a compiled part is checked on before use


COMPILE_AGREE = 1e-9  # its residual and inequalities against the numpy ones: within this x max(1, max |F|)


@dataclass(frozen=True)
class CompiledPart:
    """A Python constraint part at its condition y, traced: its residual and inequality programs."""

    residual: trace.Program
    inequality: trace.Program


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


def _parts(space: ConstrainedSpace) -> list:
    constraint = space.constraint
    return constraint.parts if isinstance(constraint, ConstraintSet) else [constraint]


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


def add_terms(core, space: ConstrainedSpace, layout: list[tuple[str, object]]) -> None:
    """Add ``space``'s constraint as ``layout`` has it (:func:`checked_layout`) to ``core``, an empty core of its
    robot (:func:`~manifoldgen.core_extension.empty_core`): its terms, tolerance and callbacks' inequalities."""
    for kind, term in layout:
        if kind == "callback":
            core.add_callback(term.rows, term.residuals)
            continue
        if kind == "expression":
            _add_compiled(core, term[2])
            continue
        core.add_term(term["type"], term)  # the core's table of built-in terms (native/src/builtin_terms.cpp)
    core.set_tolerance(np.asarray(space.constraint.tolerance, float))
    python_inequalities = _python_inequalities(space, layout)
    if python_inequalities:
        core.set_inequalities(*python_inequalities)


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
    core = empty_core(space, geometry=False)
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
