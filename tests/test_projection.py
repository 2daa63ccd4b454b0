"""Projection: known answers, convergence from random seeds, limits, honest failures."""

import numpy as np

from manifoldgen.constraints import JointLinearConstraint, project


def test_linear_constraint_projects_orthogonally(panda_task, rng):
    robot = panda_task.robot
    mid = (robot.lower + robot.upper) / 2
    q = mid + 0.2 * (robot.sample_uniform(50, rng) - mid)  # well inside the limits
    joint_sum = JointLinearConstraint(robot, [[1, 1, 0, 0, 0, 0, 0]], [[0.0], [0.5]], tolerance=1e-3)
    res = project(joint_sum, q, [0.5])
    assert res.converged.all() and np.all(res.iterations <= 6)
    shift = (0.5 - q[:, 0] - q[:, 1]) / 2  # closest point on q0 + q1 = 0.5
    np.testing.assert_allclose(res.q[:, 0], q[:, 0] + shift, atol=1e-6)
    np.testing.assert_allclose(res.q[:, 1], q[:, 1] + shift, atol=1e-6)
    np.testing.assert_allclose(res.q[:, 2:], q[:, 2:])


def test_pose_projection_converges_from_uniform_seeds_inside_limits(panda_task, rng):
    c, robot = panda_task.constraint, panda_task.robot
    res = project(c, robot.sample_uniform(500, rng), [0.45])
    assert res.converged.mean() > 0.5
    assert np.all(np.abs(c.residual(res.q[res.converged], [0.45])) <= 1e-6)
    assert robot.within_limits(res.q).all()
    assert np.median(res.iterations[res.converged]) <= 15


def test_projection_of_a_point_on_the_manifold_does_not_move_it(panda_task):
    res = project(panda_task.constraint, panda_task.home, panda_task.home_condition, tol=1e-4)
    assert res.converged[0] and res.iterations[0] == 0
    np.testing.assert_array_equal(res.q[0], panda_task.home)


def test_unreachable_condition_is_reported_as_failure(panda_task, rng):
    res = project(panda_task.constraint, panda_task.robot.sample_uniform(50, rng), [2.0], max_iters=30)
    assert not res.converged.any()
    assert np.all(res.residual > 0.5) and np.all(res.iterations == 30)


def test_per_row_conditions(panda_task, rng):
    y = np.array([[0.3], [0.5], [0.6]])
    seeds = np.repeat(panda_task.home[None], 3, axis=0)
    res = project(panda_task.constraint, seeds, y)
    assert res.converged.all()
    z = panda_task.robot.frame_pose(res.q, "panda_hand_tcp")[0][:, 2]
    np.testing.assert_allclose(z, y[:, 0], atol=1e-6)
