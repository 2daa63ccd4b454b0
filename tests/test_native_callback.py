"""Python constraints in the compiled core through batched callbacks (compilation off: the path of a residual
that does not trace), against the Python space as the oracle: residuals, Jacobians, verdicts (inequalities
included), projection, motion and path checks, and a native RRT-Connect path on the user task of docs/tasks.md
rechecked state by state with the Python rule. tests/test_native_expression.py: the same constraints compiled.
"""

from pathlib import Path

import numpy as np
import pytest

from manifoldgen import native
from manifoldgen.collision import CollisionChecker
from manifoldgen.constraints import ConstraintSet, PoseConstraint
from manifoldgen.shapes import Obstacle, Pose
from manifoldgen.space import ConstrainedSpace, densify

from planning_problems import DownAndNear

pytest.importorskip("manifoldgen_core", reason="the compiled core is not built (scripts/setup.sh builds it)")

USER_TASK = Path(__file__).resolve().parent.parent / "examples" / "user_task" / "tool-down-xarm7.toml"


@pytest.fixture(scope="module")
def user():
    """The docs' user task (xarm7, tool down at x = 0.4; Jacobian by torch autograd) among a post."""
    from manifoldgen.tasks import get_task
    task = get_task(str(USER_TASK))
    post = Obstacle("post", "box", Pose([0.4, 0.25, 0.2]), size=[0.1, 0.1, 0.4])
    space = ConstrainedSpace(task.constraint, [0.4], CollisionChecker(task.robot, obstacles=[post.geometry_object()]))
    return task, space, native.core_space(space, compile=False)


@pytest.fixture(scope="module")
def mixed(panda_task):
    """A built-in pose term (height and yaw, in C++) followed by a Python part with an inequality."""
    from manifoldgen.scene import get_scene
    robot = panda_task.robot
    down = np.diag([1.0, -1.0, -1.0])
    pose = PoseConstraint(robot, "panda_hand_tcp", down, [[0.3], [0.5]], orientation_axes=("z",))
    constraint = ConstraintSet([pose, DownAndNear(robot, "panda_hand_tcp")])
    space = ConstrainedSpace(constraint, [0.5], get_scene(panda_task, "wall").checker(robot))
    return panda_task, space, native.core_space(space, compile=False)


def _states(task, space, seed=3):
    q = task.robot.sample_uniform(50, np.random.default_rng(seed))
    q[:25] = space.project(q[:25]).q
    return q


def _codes(space, q, limit):
    """The Python rule's first failed test per row, as the core numbers them."""
    code, _ = space._failures(q, limit)
    free = code == 0
    code[free] = np.where(space.checker.in_collision(q[free]), 4, 0)
    return code


@pytest.mark.parametrize("problem", ["user", "mixed"])
def test_residuals_jacobians_and_verdicts_equal_the_python_space(problem, request):
    task, space, core = request.getfixturevalue(problem)
    assert core.batched and core.m == space.constraint.m
    q = _states(task, space)
    y = np.broadcast_to(space.y, (len(q), len(space.y)))
    calls = core.counts()["callback_calls"]
    F, J = core.jacobian(q)
    assert core.counts()["callback_calls"] == calls + 1  # one Python call for the whole batch
    F_py, J_py = space.constraint.jacobian(q, y)
    np.testing.assert_allclose(F, F_py, atol=1e-9)
    np.testing.assert_allclose(J, J_py, atol=1e-7)
    np.testing.assert_allclose(core.residual(q), F_py, atol=1e-9)
    np.testing.assert_allclose(core.violation(q), space.violation(q), atol=1e-9)
    seen = set()
    for limit in (1.0, 0.95):
        ours = core.codes(q, np.full(len(q), limit), True, True)
        assert np.array_equal(ours, _codes(space, q, limit))
        seen |= set(ours.tolist())
    assert {0, 2, 4} <= seen and (problem == "user" or 3 in seen)  # valid, off, colliding (and beyond reach)
    assert np.array_equal(native.NativeSpace(space, core).valid(q), space.valid(q))


@pytest.mark.parametrize("problem", ["user", "mixed"])
def test_projection_equals_the_python_algorithm_one_call_per_iteration(problem, request):
    task, space, core = request.getfixturevalue(problem)
    q = task.robot.sample_uniform(20, np.random.default_rng(5))
    before = core.counts()
    x, ok, iterations, residual = core.project(q, 1e-6, 50, 1e-6, 0.5)
    after = core.counts()
    reference = space.project(q)
    ok = ok.astype(bool)
    assert ok.mean() > 0.5 and np.array_equal(ok, reference.converged)
    assert np.array_equal(iterations, reference.iterations)
    np.testing.assert_allclose(x[ok], reference.q[ok], atol=1e-8)
    # every iteration evaluates the rows still moving in one Python call
    assert after["callback_calls"] - before["callback_calls"] == iterations.max() + 1
    assert after["callback_rows"] - before["callback_rows"] == (iterations + 1).sum()


def test_motion_and_path_checks_equal_the_python_space(mixed):
    task, space, core = mixed
    on = space.project(task.robot.sample_uniform(30, np.random.default_rng(2))).q
    fast = native.NativeSpace(space, core)
    stops = set()
    for k in range(0, 30, 2):
        states = densify(on[k:k + 2], 0.05)[0]
        calls = core.counts()["callback_calls"]
        assert fast.valid_prefix(states, True) == space.valid_prefix(states, True)
        assert fast.stop == space.stop
        stops.add(space.stop)
        assert core.counts()["callback_calls"] - calls <= 2  # residuals and inequalities, once per motion
    assert {"constraint", "inequality"} <= stops
    for k in range(0, 30, 3):
        path = on[k:k + 3]
        ours, reference = fast.validate_path(path), space.validate_path(path)
        assert (ours.valid, ours.reason, ours.segment, ours.states_checked) == (
            reference.valid, reference.reason, reference.segment, reference.states_checked)


def test_core_auto_plans_the_user_task_natively_and_the_path_passes_the_python_rule(user):
    from manifoldgen.planning import RRTConnect, RRTConnectSettings
    from manifoldgen.scene import get_scene
    from manifoldgen.specs import make_sampler
    task, space, _ = user
    scene = get_scene(task, "open")
    planner = RRTConnect(space, make_sampler("project", space, 0), seed=0, settings=RRTConnectSettings(compile=False))
    assert planner.core is not None and planner.core.batched
    before = planner.core.counts()
    result = planner.solve(scene.start, scene.goal, 30.0)
    after = planner.core.counts()
    assert result.solved and result.extras["core"] == "native" and "core_fallback" not in result.extras
    path = result.path
    np.testing.assert_allclose(path[0], scene.start)
    np.testing.assert_allclose(path[-1], scene.goal)
    states = densify(path, space.settings.resolution)[0]
    assert space.constraint.violation(states, space.y).max() <= 1.0
    assert task.robot.within_limits(states).all() and not space.checker.in_collision(states).any()
    assert space.validate_path(path).valid
    calls = after["callback_calls"] - before["callback_calls"]
    rows = after["callback_rows"] - before["callback_rows"]
    assert calls > 0 and rows > calls  # batches: more configurations than calls
    assert result.extras["callbacks"] == {"calls": calls, "rows": rows}
