"""OMPL baselines with our constraint: solved paths are valid, Python samplers feed OMPL's planners."""

import numpy as np
import pytest

from manifoldgen.collision import CollisionChecker
from manifoldgen.constraints import project
from manifoldgen.errors import ManifoldgenError
from manifoldgen.ompl_bridge import OmplConstraint, OmplPlanner
from manifoldgen.sampling import ProjectionSampler
from manifoldgen.space import ConstrainedSpace


@pytest.fixture(scope="module")
def setup():
    from manifoldgen.tasks import get_task
    task = get_task("pose", "panda")
    return task, task.constraint, task.home_condition, CollisionChecker(task.robot)


def _space(setup):
    task, constraint, y, checker = setup
    return ConstrainedSpace(constraint, y, checker)


def _goal(task, offset):
    return project(task.constraint, task.home + np.array(offset), task.home_condition, tol=1e-8).q[0]


class RecordingSampler(ProjectionSampler):
    """A projection sampler remembering every configuration it hands out."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.handed = []

    def sample(self):
        q = super().sample()
        self.handed.append(q)
        return q


def _check_path(result, task, y, checker, start, goal, tolerance):
    assert result.solved and result.extras["ompl_solved"] and result.extras["valid"]
    path = result.path
    np.testing.assert_allclose(path[0], start, atol=1e-12)
    np.testing.assert_allclose(path[-1], goal, atol=1e-12)
    # OMPL's own states (densified by its interpolate) keep its tolerance, which implies ours ...
    assert np.all(task.constraint.violation(path, y) <= tolerance + 1e-9)
    assert not checker.in_collision(path).any()
    # ... and every straight segment between them passes the independent dense check
    report = ConstrainedSpace(task.constraint, y, checker).validate_path(path)
    assert report.valid, report.reason
    assert result.length == pytest.approx(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


@pytest.mark.slow
@pytest.mark.parametrize("space,seed", [("projected", 2), ("atlas", 0), ("tangent", 0)])
def test_constrained_spaces_solve_and_paths_validate(setup, space, seed):
    task, constraint, y, checker = setup
    goal = _goal(task, [0.3, 0, 0, 0, 0, 0, 0.3])
    planner = OmplPlanner(_space(setup), ompl_space=space, planner="rrtconnect", seed=seed)
    result = planner.solve(task.home, goal, 20.0)
    _check_path(result, task, y, checker, task.home, goal, 1 - planner.space.settings.margin)
    assert result.planner == f"ompl-{space}-rrtconnect"
    assert result.extras["newton_steps"] > 0
    # OMPL projects through Constraint::project only in the projected space (atlas and tangent use charts)
    assert (result.projections > 0) == (space == "projected")


def test_same_seed_same_path(setup):
    task, constraint, y, checker = setup
    goal = _goal(task, [0.4, 0.3, 0, 0.3, 0, 0, 0])
    paths = [OmplPlanner(_space(setup), ompl_space="atlas", seed=3).solve(task.home, goal, 10.0).path
             for _ in range(2)]
    np.testing.assert_array_equal(paths[0], paths[1])


@pytest.mark.parametrize("space,planner", [("joint", "prm"), ("atlas", "bkpiece")])
def test_python_sampler_feeds_ompl_planners(setup, space, planner):
    task, constraint, y, checker = setup
    goal = _goal(task, [1.2, 0.3, 0, 0.5, 0, 0, 0])
    sampler = RecordingSampler(_space(setup), seed=0)
    result = OmplPlanner(_space(setup), sampler, ompl_space=space, planner=planner, seed=0).solve(
        task.home, goal, 20.0)
    assert result.extras["sampler_calls"] >= 1
    assert result.samples_drawn == len(sampler.handed) >= 1
    handed = np.array(sampler.handed)
    assert constraint.satisfied(handed, y).all() and not checker.in_collision(handed).any()
    _check_path(result, task, y, checker, task.home, goal, 1.0)
    if space == "joint":  # a straight joint-space edge needs the sampler's states: they are the path's corners
        corners = result.path[1:-1][np.linalg.norm(np.diff(result.path, 2, axis=0), axis=1) > 1e-9]
        assert all(np.min(np.linalg.norm(handed - c, axis=1)) < 1e-12 for c in corners)


def test_ompl_constraint_scaling(setup):
    task, constraint, y, _ = setup
    ompl_constraint = OmplConstraint(constraint, y, tolerance=1.0)
    rng = np.random.default_rng(0)
    q = task.home + 0.02 * rng.standard_normal((50, task.robot.n))
    F = constraint.residual(q, y)
    for qi, Fi in zip(q, F):
        out = np.zeros(constraint.m)
        ompl_constraint.function(qi, out)
        np.testing.assert_allclose(out, Fi / constraint.tolerance)
        # OMPL's norm test never accepts what our per-component test rejects
        if ompl_constraint.isSatisfied(qi):
            assert constraint.violation(qi, y)[0] <= 1.0
    J = np.zeros((constraint.m, task.robot.n))
    ompl_constraint.jacobian(q[0], J)
    np.testing.assert_allclose(J, constraint.jacobian(q[:1], y)[1][0] / constraint.tolerance[:, None])


def test_refusals(setup):
    task, constraint, y, checker = setup
    space = _space(setup)
    sampler = ProjectionSampler(ConstrainedSpace(constraint, y), seed=0)
    with pytest.raises(ManifoldgenError, match="cannot use a Python sampler"):
        OmplPlanner(space, sampler, planner="rrtconnect")
    with pytest.raises(ManifoldgenError, match="unknown OMPL space"):
        OmplPlanner(space, ompl_space="atlass")
    with pytest.raises(ManifoldgenError, match="needs a sampler"):
        OmplPlanner(space, ompl_space="joint", planner="prm")
    with pytest.raises(ManifoldgenError, match="the sampler serves condition"):
        OmplPlanner(space, ProjectionSampler(ConstrainedSpace(constraint, y + 0.05)), planner="prm")
    with pytest.raises(ManifoldgenError, match="violates the constraint"):
        OmplPlanner(space, ompl_space="atlas").solve(task.home + 0.3, task.home, 1.0)
