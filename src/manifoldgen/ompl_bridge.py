"""OMPL baselines: our constraint and collision checker inside OMPL's constrained planning.

:class:`OmplPlanner` has the :class:`~manifoldgen.planning.base.Planner` contract
(``solve(start, goal, time_limit) -> PlanResult``) and plans with OMPL 2's own planners
(RRTConnect, RRT, KPIECE1, PRM, PRMstar, BKPIECE1) in one of four spaces:

- ``projected``, ``atlas``, ``tangent``: OMPL's ProjectedStateSpace, AtlasStateSpace and
  TangentBundleStateSpace over the joint box, with :class:`OmplConstraint` (our residual
  and Jacobian at a fixed ``y``). OMPL samples, projects and walks the manifold itself.
- ``joint``: the plain joint box; validity includes the constraint and motions are
  straight segments checked every ``resolution`` rad, as MoveIt does with path
  constraints (the paper's setting). Only useful with a sampler that lands on the manifold.

Validity is the :class:`~manifoldgen.space.ConstrainedSpace`'s (in the constrained spaces
without the equality test: OMPL keeps its states on the manifold itself).

A :class:`~manifoldgen.sampling.Sampler` (learned model, PG, projection, uniform) enters
OMPL *unmodified* planners through ``si.setValidStateSamplerAllocator``: OMPL's PRM,
PRMstar and BKPIECE1 then draw their states from it (:class:`SamplerBridge`); the tree
planners RRT, RRTConnect and KPIECE1 have no Python state-sampler hook in OMPL 2.0.1's
bindings, so they refuse a sampler.

The returned path is OMPL's solution densified by OMPL's ``interpolate`` and then checked
by the space's :meth:`~manifoldgen.space.ConstrainedSpace.validate_path`:
OMPL guarantees only its own states (to its tolerance, ``delta`` apart on the manifold),
not the straight segments between them. A path that fails the check does not end the query: as
our planners cut a rejected edge and go on, OMPL searches again (``SimpleSetup::clear``: a new
tree; the atlas keeps its charts) within the time left. ``solved`` requires OMPL's exact solution
*and* a valid path; ``extras`` keeps both verdicts, the attempts, the rejected paths, the worst
violation and the reason.
Constraint evaluations are our batched numpy code called one state at a time, so OMPL
pays Python overhead on every Newton step: ``projections`` counts calls of OMPL's
``Constraint::project`` (the projected space; atlas and tangent bundle project through
their charts), ``extras`` every space's Newton steps and residual evaluations.
"""

from __future__ import annotations

import time

import numpy as np

from manifoldgen.constraints import Constraint
from manifoldgen.errors import ManifoldgenError, require
from manifoldgen.ompl_settings import OmplSettings
from manifoldgen.planning.base import check_time_limit
from manifoldgen.planning.result import PlanResult, path_length
from manifoldgen.sampling import Sampler
from manifoldgen.space import ConstrainedSpace

ob = require("ompl.base", "ompl", "the OMPL bridge")
og = require("ompl.geometric", "ompl", "the OMPL bridge")
ou = require("ompl.util", "ompl", "the OMPL bridge")

SPACES = ("projected", "atlas", "tangent", "joint")
PLANNERS = {"rrtconnect": og.RRTConnect, "rrt": og.RRT, "kpiece": og.KPIECE1, "prm": og.PRM,
            "prmstar": og.PRMstar, "bkpiece": og.BKPIECE1}
SAMPLER_PLANNERS = ("prm", "prmstar", "bkpiece")  # call a Python ValidStateSampler


class OmplConstraint(ob.Constraint):
    """Our ``constraint`` at a fixed ``y`` as an OMPL constraint on ``R^n``.

    OMPL has one scalar tolerance, compared with the Euclidean norm of F. We hand OMPL the
    residual scaled component-wise by our tolerances, ``F_i / tol_i``, and give OMPL the
    tolerance ``t = 1 - margin``. OMPL's test ``||F / tol||_2 <= t`` then implies ours
    (``max_i |F_i| / tol_i <= 1``): it is never looser, in every component proportionally
    (metres and radians weighted by their own tolerance), and at most ``sqrt(m)`` stricter
    along a diagonal. Using the strictest component's tolerance instead would tighten every
    other component by the ratio of tolerances. Newton steps are unchanged by the row
    scaling (for a full-rank Jacobian), so OMPL's projection behaves as on the raw residual.
    """

    def __init__(self, constraint: Constraint, y: np.ndarray, tolerance: float = 1.0, max_iterations: int = 50):
        super().__init__(constraint.robot.n, constraint.m, tolerance)
        self.setMaxIterations(max_iterations)
        self.constraint = constraint
        self.y = np.asarray(y, dtype=float).reshape(1, constraint.condition.k)
        self.scale = 1.0 / constraint.tolerance
        self.function_evals = 0
        self.jacobian_evals = 0
        self.projections = 0

    def function(self, x, out) -> None:
        """out (m,) = F(x, y) / tol."""
        self.function_evals += 1
        out[:] = self.constraint.residual(np.asarray(x)[None], self.y)[0] * self.scale

    def jacobian(self, x, out) -> None:
        """out (m, n) = dF/dq (x, y) / tol (row-scaled)."""
        self.jacobian_evals += 1
        out[:] = self.constraint.jacobian(np.asarray(x)[None], self.y)[1][0] * self.scale[:, None]

    def project(self, x) -> bool:
        """OMPL's own Newton projection, counted."""
        self.projections += 1
        return ob.Constraint.project(self, x)


def read_state(state, n: int) -> np.ndarray:
    """An OMPL state (real vector or constrained) as a (n,) array."""
    return np.fromiter((state[i] for i in range(n)), float, n)


def write_state(state, q: np.ndarray, constrained: bool) -> None:
    """Set an OMPL state from ``q (n,)`` (constrained states take ``copy``; real vectors, items)."""
    if constrained:
        state.copy(q.tolist())
    else:
        for i, value in enumerate(q.tolist()):
            state[i] = value


class SamplerBridge(ob.ValidStateSampler):
    """OMPL ValidStateSampler drawing from one of our Samplers (the paper's Algorithm 1 buffer).

    ``sample`` copies the next configuration into OMPL's state; in a constrained space a
    state outside OMPL's (slightly stricter) tolerance is first projected by OMPL. ``sampleNear``
    draws a configuration and moves from ``near`` toward it by at most ``distance`` with the
    space's own interpolation (on the manifold for constrained spaces). ``calls`` and
    ``drawn`` count OMPL's requests and our samples.
    """

    def __init__(self, si: ob.SpaceInformation, sampler: Sampler, constraint: OmplConstraint | None, attempts: int):
        super().__init__(si)
        self.setName("manifoldgen")
        self.si, self.sampler, self.constraint, self.attempts = si, sampler, constraint, attempts
        self.scratch = si.allocState()
        self.calls = self.drawn = 0

    def _draw(self, state) -> bool:
        """Copy one sampler configuration into ``state``; False when the sampler gave up."""
        try:
            q = self.sampler.sample()
        except ManifoldgenError:
            return False
        self.drawn += 1
        write_state(state, q, self.constraint is not None)
        if self.constraint is None:
            return True
        return self.constraint.isSatisfied(state) or (self.constraint.project(state) and self.si.isValid(state))

    def sample(self, state) -> bool:
        self.calls += 1
        return any(self._draw(state) for _ in range(self.attempts))

    def sampleNear(self, state, near, distance) -> bool:
        self.calls += 1
        space = self.si.getStateSpace()
        for _ in range(self.attempts):
            if not self._draw(self.scratch):
                continue
            gap = self.si.distance(near, self.scratch)
            space.interpolate(near, self.scratch, min(1.0, distance / max(gap, 1e-12)), state)
            if self.si.isValid(state):
                return True
        return False


class OmplPlanner:
    """OMPL ``planner`` in the OMPL state space ``ompl_space`` for our constrained ``space``; see
    the module docstring.

    sampler: our Sampler for PRM / PRMstar / BKPIECE1 (None: OMPL's own sampling);
    resolution: OMPL's manifold step ``delta`` (constrained spaces) or the straight-segment
    check resolution (``joint``), in rad; seed: OMPL's global RNG seed, set before each
    solve, so the same seed gives the same run in any process (except PRM / PRMstar, which
    grow their roadmap in a second thread).
    """

    def __init__(self, space: ConstrainedSpace, sampler: Sampler | None = None, *, ompl_space: str = "projected",
                 planner: str = "rrtconnect", resolution: float = 0.05, seed: int = 0,
                 settings: OmplSettings | None = None):
        if ompl_space not in SPACES:
            raise ManifoldgenError(f"unknown OMPL space '{ompl_space}'; known: {', '.join(SPACES)}")
        if planner not in PLANNERS:
            raise ManifoldgenError(f"unknown OMPL planner '{planner}'; known: {', '.join(PLANNERS)}")
        if sampler is not None and planner not in SAMPLER_PLANNERS:
            raise ManifoldgenError(f"OMPL's {planner} cannot use a Python sampler (no state-sampler binding); "
                                   f"use one of {', '.join(SAMPLER_PLANNERS)} or no sampler")
        if sampler is None and ompl_space == "joint":
            raise ManifoldgenError("the 'joint' space needs a sampler that lands on the manifold (uniform "
                                   "joint samples almost never satisfy the constraint); pass one or use "
                                   "a constrained space")
        if sampler is not None and not np.array_equal(sampler.space.y, space.y):
            raise ManifoldgenError(f"the sampler serves condition {sampler.space.y.tolist()}, the planner "
                                   f"{space.y.tolist()}; make both for the same condition")
        if resolution <= 0:
            raise ManifoldgenError(f"resolution must be positive, got {resolution}")
        self.settings = OmplSettings() if settings is None else settings
        self.settings.check()
        self.space, self.sampler = space, sampler
        self.ompl_space, self.planner_name, self.resolution, self.seed = ompl_space, planner, resolution, seed
        self.name = f"ompl-{ompl_space}-{planner}"

    # ---------------------------------------------------------------- building blocks
    def _ambient(self) -> ob.RealVectorStateSpace:
        robot = self.space.robot
        box = ob.RealVectorStateSpace(robot.n)
        bounds = ob.RealVectorBounds(robot.n)
        for i in range(robot.n):
            bounds.setLow(i, float(robot.lower[i]))
            bounds.setHigh(i, float(robot.upper[i]))
        box.setBounds(bounds)
        return box

    def _spaces(self, ompl_constraint: OmplConstraint | None):
        """(state space, space information) for ``self.ompl_space``."""
        box = self._ambient()
        if self.ompl_space == "joint":
            si = ob.SpaceInformation(box)
            si.setStateValidityCheckingResolution(self.resolution / box.getMaximumExtent())
            return box, si
        kind = {"projected": ob.ProjectedStateSpace, "atlas": ob.AtlasStateSpace,
                "tangent": ob.TangentBundleStateSpace}[self.ompl_space]
        space = kind(box, ompl_constraint)
        si = (ob.TangentBundleSpaceInformation if self.ompl_space == "tangent" else ob.ConstrainedSpaceInformation)(space)
        space.setDelta(self.resolution)
        space.setLambda(self.settings.lambda_)
        if self.ompl_space != "projected":  # the atlas's knobs, as the C++ baseline sets them
            space.setEpsilon(self.settings.epsilon)
            space.setAlpha(self.settings.alpha)
            space.setExploration(self.settings.exploration)  # before rho: it resets the sampling radius from rho
            space.setRho(self.settings.rho or 5 * self.resolution)
            space.setSeparated(self.settings.separated)
        return space, si

    def _state(self, space, q: np.ndarray):
        state = space.allocState()
        write_state(state, q, self.ompl_space != "joint")
        return state

    # ---------------------------------------------------------------- the contract
    def solve(self, start: np.ndarray, goal: np.ndarray, time_limit: float) -> PlanResult:
        """Plan from ``start (n,)`` to ``goal (n,)`` within ``time_limit`` seconds."""
        check_time_limit(time_limit)
        n, joint = self.space.n, self.ompl_space == "joint"
        start, goal = (self.space.check_query_state(q, what) for q, what in ((start, "start"), (goal, "goal")))
        _seed_ompl(self.seed)
        began = time.perf_counter()
        margin = self.space.settings.margin
        ompl_constraint = None if joint else OmplConstraint(self.space.constraint, self.space.y, 1.0 - margin,
                                                             self.settings.max_iterations)
        space, si = self._spaces(ompl_constraint)
        valid = self.space.valid
        si.setStateValidityChecker(lambda state: bool(valid(read_state(state, n)[None], equality=joint)[0]))
        bridge = []
        if self.sampler is not None:
            def allocate(info):
                bridge.append(SamplerBridge(info, self.sampler, ompl_constraint, self.settings.sample_attempts))
                return bridge[-1]
            si.setValidStateSamplerAllocator(allocate)
        try:
            setup = og.SimpleSetup(si)
            states = [self._state(space, q) for q in (start, goal)]
            if ompl_constraint is not None:
                for state, what in zip(states, ("start", "goal")):
                    if not ompl_constraint.isSatisfied(state):
                        raise ManifoldgenError(f"{what} is within our tolerance but not within OMPL's stricter one "
                                               f"(norm of the tolerance-scaled residual <= {1 - margin:g}); "
                                               f"project it onto the constraint more tightly")
            if self.ompl_space in ("atlas", "tangent"):
                for state in states:
                    space.anchorChart(state)
            setup.setStartAndGoalStates(*states)
            planner = PLANNERS[self.planner_name](si)
            if self.settings.range and hasattr(planner, "setRange"):
                planner.setRange(self.settings.range)
            setup.setPlanner(planner)
            setup.setup()
            exact, attempts, rejected, vertices, report, status = False, 0, 0, 0, None, "not run"
            path = np.zeros((0, n))
            while (remaining := float(time_limit) - (time.perf_counter() - began)) > 0:
                if attempts:  # our dense check refused OMPL's path: search again (the atlas keeps its charts)
                    setup.clear()
                attempts += 1
                status = setup.solve(remaining)
                data = ob.PlannerData(si)
                setup.getPlannerData(data)
                vertices += int(data.numVertices())
                exact = bool(setup.haveExactSolutionPath())
                if not exact:
                    break
                solution = setup.getSolutionPath()
                solution.interpolate()
                path = np.array([read_state(state, n) for state in solution.getStates()])
                report = self.space.validate_path(path)
                if report.valid:
                    break
                rejected += 1
            elapsed = time.perf_counter() - began
            extras = {"space": self.ompl_space, "ompl_planner": self.planner_name, "ompl_status": str(status),
                      "ompl_solved": exact or rejected > 0, "vertices": vertices, "resolution": self.resolution,
                      "ompl_tolerance": 1.0 - margin, "attempts": attempts, "rejected_paths": rejected}
            if self.ompl_space in ("atlas", "tangent"):
                extras["charts"] = int(space.getChartCount())
            drawn = sum(b.drawn for b in bridge)
            if bridge:
                extras["sampler_calls"] = sum(b.calls for b in bridge)
                extras["sampler"] = self.sampler.stats.to_dict()
        finally:  # the allocator's closure holds the samplers, which hold the SpaceInformation: a cycle through C++
            if self.sampler is not None:
                si.clearValidStateSamplerAllocator()
        if report is not None:
            extras.update(valid=report.valid, worst_violation=report.worst_violation, reason=report.reason)
        if ompl_constraint is not None:
            extras.update(function_evals=ompl_constraint.function_evals, newton_steps=ompl_constraint.jacobian_evals)
        solved = exact and report is not None and report.valid
        projections = ompl_constraint.projections if ompl_constraint is not None else 0
        return PlanResult(solved, path if solved else np.zeros((0, n)), elapsed, vertices, drawn,
                          projections, self.name, path_length(path) if solved else 0.0, extras)


def _seed_ompl(seed: int) -> None:
    """Seed OMPL's global RNG and keep OMPL's log to warnings and errors.

    OMPL rejects seed 0 (we add 1) and logs an error, harmless here, when reseeded after
    its first random numbers: later OMPL objects are still seeded from the new seed.
    """
    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(int(seed) % (2**31 - 1) + 1)
    ou.setLogLevel(ou.LOG_WARN)
