"""User residuals compiled into the core (constraints/trace.py traces them, native/src/expression.cpp runs them):
the compiled residual and Jacobian against the numpy residual and torch autograd's Jacobian on random
configurations (docs/tasks.md's tool_down.py, and synthetic residuals using every recorded operation on a fixed
arm, an arm with a prismatic and continuous joints, and a floating base), compiled inequalities against the
Python verdicts, residuals the tracer refuses or that compile wrong falling back to callbacks (with the reason),
and a planned path on the user task checked with the Python rule.
"""

from pathlib import Path

import numpy as np
import pytest

from manifoldgen import native
from manifoldgen.collision import CollisionChecker
from manifoldgen.constraints import Condition, Constraint, array_namespace, as_like
from manifoldgen.constraints import trace
from manifoldgen.shapes import Obstacle, Pose
from manifoldgen.space import ConstrainedSpace, densify

from planning_problems import DownAndNear

core_module = pytest.importorskip("manifoldgen_core",
                                  reason="the compiled core is not built (scripts/setup.sh builds it)")

USER_TASK = Path(__file__).resolve().parent.parent / "examples" / "user_task" / "tool-down-xarm7.toml"
AGREE = 1e-9


def _frames(robot) -> tuple[str, str]:
    """Two frames the planning group moves: on its last joint and on one halfway along it."""
    joints = robot._joint_ids
    return tuple(next(f.name for f in robot.model.frames if f.parentJoint == j)
                 for j in (joints[-1], joints[len(joints) // 2]))


# Synthetic residuals: (c, q, y) -> (B, m) in array-API operations (numpy and torch alike); c.a, c.b: frame names.
def _index(c, q, y):
    xp = array_namespace(q)
    p, R = c.robot.frame_pose(q, c.a)
    return xp.concat([p[:, :1] - y, R[:, :2, 2], R[..., 1, ::2], p[:, [2, 0]], q[:, 1:3],
                      xp.reshape(R, (-1, 9))[:, 4:6], R[:, 0][:, None, 1]], axis=1)


def _arithmetic(c, q, y):
    xp = array_namespace(q)
    p, R = c.robot.frame_pose(q, c.a)
    scale = as_like(np.array([[1.0, -2.0, 0.5]]), p)  # (1, 3): broadcast along the batch axis
    columns = [p[:, 0] * p[:, 1] - 2.0 * p[:, 2] / (2.0 + R[:, 2, 2]), -p[:, 0] + 0.3, (p[:, 1] + 1.0) ** 3,
               2.0 ** p[:, 2], (1.5 + R[:, 0, 0]) ** R[:, 1, 1], 1.0 - q[:, 0] / 3.0, +p[:, 1] - y[:, 0]]
    return xp.concat([xp.stack(columns, axis=1), p * scale + 0.25, (p - 1.0) / (p + 2.0)], axis=1)


def _matmul(c, q, y):
    xp = array_namespace(q)
    p, R = c.robot.frame_pose(q, c.a)
    pb, Rb = c.robot.frame_pose(q, c.b)
    M = as_like(np.array([[0.0, 1.0, 2.0], [-1.0, 0.5, 0.0], [3.0, 0.0, 1.0]]), R)
    parts = [R @ as_like(np.array([0.2, -0.4, 1.0]), R),          # (B, 3, 3) @ (3,)
             xp.reshape(M @ R, (-1, 9)),                          # (3, 3) @ (B, 3, 3)
             xp.reshape(xp.matrix_transpose(R) @ Rb, (-1, 9)),    # (B, 3, 3) @ (B, 3, 3)
             xp.reshape(R.mT - xp.permute_dims(Rb, (0, 2, 1)), (-1, 9)),
             (p[:, None, :] @ Rb)[:, 0],                          # (B, 1, 3) @ (B, 3, 3)
             p @ as_like(M[:, :2], p),                            # (B, 3) @ (3, 2)
             (pb - p) @ as_like(np.array([1.0, 2.0, 3.0]), p)[:, None]]
    return xp.concat(parts, axis=1)


def _reductions(c, q, y):
    xp = array_namespace(q)
    p, R = c.robot.frame_pose(q, c.a)
    pb, Rb = c.robot.frame_pose(q, c.b)
    columns = [xp.sum(R * Rb, axis=(1, 2)), xp.mean(p, axis=1), xp.prod(p + 2.0, axis=-1), xp.vecdot(p, pb),
               xp.linalg.vector_norm(p - pb, axis=-1)]
    return xp.concat([xp.stack(columns, axis=1), xp.max(R, axis=1), xp.min(Rb, axis=-1),
                      xp.linalg.cross(p, pb), xp.sum(p, axis=1, keepdims=True)], axis=1)


def _functions(c, q, y):
    xp = array_namespace(q)
    p, R = c.robot.frame_pose(q, c.a)
    columns = [xp.sqrt(p[:, 0] ** 2 + 0.1), xp.sin(p[:, 1]), xp.cos(q[:, 0]), xp.tan(0.5 * R[:, 0, 0]),
               xp.asin(0.9 * R[:, 2, 2]), xp.acos(0.9 * R[:, 1, 2]), xp.atan(p[:, 2]), xp.atan2(R[:, 1, 0], R[:, 0, 0]),
               xp.exp(p[:, 0]), xp.log(1.0 + p[:, 1] ** 2), xp.tanh(p[:, 2]), xp.abs(p[:, 0] - 0.05),
               xp.maximum(p[:, 0], p[:, 1]), xp.minimum(p[:, 2], 0.1), xp.clip(p[:, 1], -0.05, 0.05),
               xp.square(R[:, 0, 1]), xp.negative(p[:, 2]), xp.subtract(p[:, 0], xp.multiply(p[:, 1], 2.0)),
               xp.divide(xp.add(p[:, 0], 1.0), 3.0), xp.pow(1.2 + R[:, 2, 0], 1.5)]
    return xp.stack(columns, axis=-1)


def _shapes_and_com(c, q, y):
    xp = array_namespace(q)
    p, R = c.robot.frame_pose(q, c.a)
    com = c.robot.com(q)
    stacked = xp.stack([p, com], axis=1)                           # (B, 2, 3)
    flat = xp.reshape(xp.expand_dims(stacked, axis=1), (-1, 6))    # (B, 1, 2, 3) -> (B, 6)
    return xp.concat([flat, xp.squeeze(p[:, None, :2], axis=1) - com[:, :2], (com[:, None, :] @ R)[:, 0],
                      xp.zeros_like(p[:, :1]) + xp.ones_like(com[:, :1]) * com[:, 2:]], axis=1)


CASES = {"index": _index, "arithmetic": _arithmetic, "matmul": _matmul, "reductions": _reductions,
         "functions": _functions, "shapes_and_com": _shapes_and_com}


class Synthetic(Constraint):
    """A test's constraint: the residual CASES[case] on two frames of the robot, conditioned on one value."""

    def __init__(self, robot, case, residual=None):
        self.robot, self.case = robot, case
        self.a, self.b = _frames(robot)
        self._residual = residual or CASES[case]
        self.condition = Condition(("v",), ("m",), np.array([[0.4]]))
        q = robot.sample_uniform(1, np.random.default_rng(0))
        self.tolerance = np.full(self._residual(self, q, np.full((1, 1), 0.4)).shape[1], 0.01)

    def residual(self, q, y):
        q, y = self.batch(q, y)
        return self._residual(self, q, y)


@pytest.fixture(scope="module")
def robots():
    from manifoldgen.tasks import get_task
    return {"xarm7": get_task(str(USER_TASK)).robot,  # revolute joints
            "pr2": get_task("pose", "pr2").robot,  # a prismatic torso and continuous joints
            "talos": get_task("balance", "talos").robot}  # a floating base


def _compare(constraint, y, rows=40, seed=0):
    """The compiled core's residual and Jacobian against numpy and autograd on random rows: (space, core)."""
    space = ConstrainedSpace(constraint, y)
    core = native.core_space(space)
    assert not core.batched and native.compile_report(space)["callbacks"] == {}
    q = constraint.robot.sample_uniform(rows, np.random.default_rng(seed))
    ys = np.broadcast_to(space.y, (rows, len(space.y)))
    F, J = core.jacobian(q)
    np.testing.assert_allclose(F, constraint.residual(q, ys), rtol=0, atol=AGREE)
    np.testing.assert_allclose(core.residual(q), F, rtol=0, atol=1e-14)  # pinocchio's two kinematics passes
    _, J_autograd = constraint.jacobian(q, ys)
    np.testing.assert_allclose(J, J_autograd, rtol=0, atol=AGREE)
    assert np.abs(J_autograd).max() > 0.1
    return space, core


def test_the_user_task_runs_compiled_equal_to_numpy_and_autograd():
    from manifoldgen.tasks import get_task
    task = get_task(str(USER_TASK))
    space, core = _compare(task.constraint, [0.4], rows=200)
    assert native.compile_report(space)["compiled"] == ["tool_down:ToolDownAtX"]
    q = task.robot.sample_uniform(20, np.random.default_rng(5))  # projection: the Python algorithm's steps
    x, ok, iterations, _ = core.project(q, 1e-6, 50, 1e-6, 0.5)
    reference = space.project(q)
    ok = ok.astype(bool)
    assert ok.mean() > 0.5 and np.array_equal(ok, reference.converged)
    assert np.array_equal(iterations, reference.iterations)
    np.testing.assert_allclose(x[ok], reference.q[ok], atol=1e-8)
    assert core.counts()["callback_calls"] == 0


@pytest.mark.parametrize("robot", ["xarm7", "pr2", "talos"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_every_recorded_operation_runs_compiled_equal_to_numpy_and_autograd(robots, robot, case):
    _compare(Synthetic(robots[robot], case), [0.4], seed=len(case))


def test_the_cases_use_every_operation_the_core_has(robots):
    """The cases above exercise every operation of a program, and the tracer's names are the core's."""
    assert set(trace.OPS) == set(core_module.Op.__members__)
    used = set()
    for case in CASES:
        residual, _ = trace.trace(Synthetic(robots["xarm7"], case), np.array([0.4]), robots["xarm7"])
        used |= {op for op, _, _ in residual.code}
    assert used == set(trace.OPS)


def test_compiled_inequalities_give_the_python_verdicts(robots):
    robot = robots["xarm7"]
    post = Obstacle("post", "box", Pose([0.4, 0.25, 0.2]), size=[0.1, 0.1, 0.4])
    checker = CollisionChecker(robot, obstacles=[post.geometry_object()])
    space = ConstrainedSpace(DownAndNear(robot, "link_eef", reach=0.2), [], checker)
    core = native.core_space(space)
    assert not core.batched and core.p == 0 and core.g == 1  # compiled inequality: none left to Python
    q = robot.sample_uniform(60, np.random.default_rng(3))
    q[:30] = space.project(q[:30]).q
    np.testing.assert_allclose(core.inequality(q), space.constraint.inequality(q, np.zeros((60, 0))), atol=AGREE)
    seen = set()
    for limit in (1.0, 0.95):
        code, _ = space._failures(q, limit)
        free = code == 0
        code[free] = np.where(space.checker.in_collision(q[free]), 4, 0)
        ours = core.codes(q, np.full(len(q), limit), True, True)
        assert np.array_equal(ours, code)
        seen |= set(ours.tolist())
    assert {0, 2, 3} <= seen  # valid, off the manifold, beyond reach
    fast, on = native.NativeSpace(space, core), q[:30]
    for k in range(0, 28, 2):
        states = densify(on[k:k + 2], 0.05)[0]
        assert fast.valid_prefix(states, True) == space.valid_prefix(states, True) and fast.stop == space.stop


# Residuals the tracer refuses: (c, q, y) -> (B, m) (numpy works; the trace does not), and the reason's words.
def _where(c, q, y):
    xp = array_namespace(q)
    p, _ = c.robot.frame_pose(q, c.a)
    return xp.where(p[:, :1] > 0, p[:, :1], -p[:, :1])


def _branch(c, q, y):
    p, _ = c.robot.frame_pose(q, c.a)
    return p[:, :1] if (p[:, 0] > -10.0).all() else -p[:, :1]


def _numpy_function(c, q, y):
    p, _ = c.robot.frame_pose(q, c.a)
    return np.sin(p[:, :1])


def _robot_method(c, q, y):
    return c.robot.frame_jacobian(q, c.a)[0][:, :1]


def _across_rows(c, q, y):
    xp = array_namespace(q)
    p, _ = c.robot.frame_pose(q, c.a)
    return p[:, :1] - xp.mean(p[:, :1], axis=0)


def _moved_q(c, q, y):
    p, _ = c.robot.frame_pose(q + 0.1, c.a)
    return p[:, :1]


REFUSED = {"where": (_where, "where is not recorded"), "branch": (_branch, "comparison"),
           "numpy function": (_numpy_function, "does not support ufuncs"),
           "robot method": (_robot_method, "numpy array"), "across rows": (_across_rows, "batch axis"),
           "moved q": (_moved_q, "other than the traced q")}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_a_residual_that_does_not_trace_runs_through_callbacks_with_the_reason(robots, case):
    residual, words = REFUSED[case]
    constraint = Synthetic(robots["xarm7"], case, residual)
    with pytest.raises(trace.Untraceable, match=words):
        trace.trace(constraint, np.array([0.4]), robots["xarm7"])
    space = ConstrainedSpace(constraint, [0.4])
    core = native.core_space(space)
    report = native.compile_report(space)
    assert core.batched and report["compiled"] == []
    assert words in report["callbacks"][constraint.spec()["type"]]
    q = robots["xarm7"].sample_uniform(9, np.random.default_rng(1))
    np.testing.assert_allclose(core.residual(q), constraint.residual(q, np.full((9, 1), 0.4)), atol=1e-12)


def _row_count(c, q, y):
    """Depends on the batch size (len(q) is 1 while traced): compiles, and then disagrees with numpy."""
    p, _ = c.robot.frame_pose(q, c.a)
    return p[:, :1] - 0.01 * len(q)


def test_a_compiled_residual_that_disagrees_with_numpy_runs_through_callbacks(robots):
    constraint = Synthetic(robots["xarm7"], "row count", _row_count)
    trace.trace(constraint, np.array([0.4]), robots["xarm7"])  # it traces
    space = ConstrainedSpace(constraint, [0.4])
    with pytest.warns(UserWarning, match="compiled residual differs from its numpy residual"):
        core = native.core_space(space)
    assert core.batched and "differs from its numpy residual" in native.compile_report(space)["callbacks"][
        constraint.spec()["type"]]
    q = robots["xarm7"].sample_uniform(5, np.random.default_rng(1))
    np.testing.assert_allclose(core.residual(q), constraint.residual(q, np.full((5, 1), 0.4)), atol=1e-12)


def test_a_planned_path_on_the_compiled_user_task_passes_the_python_rule():
    from manifoldgen.planning import RRTConnect
    from manifoldgen.scene import get_scene
    from manifoldgen.specs import make_sampler
    from manifoldgen.tasks import get_task
    task = get_task(str(USER_TASK))
    scene = get_scene(task, "open")
    space = ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))
    planner = RRTConnect(space, make_sampler("project", space, 0), seed=0)
    result = planner.solve(scene.start, scene.goal, 30.0)
    assert result.solved and result.extras["core"] == "native"
    assert result.extras["compiled"] == ["tool_down:ToolDownAtX"] and "callbacks" not in result.extras
    assert "compile_fallback" not in result.extras
    states = densify(result.path, space.settings.resolution)[0]
    assert space.constraint.violation(states, space.y).max() <= 1.0
    assert task.robot.within_limits(states).all() and not space.checker.in_collision(states).any()
    assert space.validate_path(result.path).valid


def test_compiled_and_callback_parts_of_one_set_keep_their_rows(robots):
    """A set of a part that compiles (with an inequality) and one that does not: rows in order, each part's way."""
    from manifoldgen.constraints import ConstraintSet
    robot = robots["xarm7"]
    constraint = ConstraintSet([Synthetic(robot, "where", _where), DownAndNear(robot, "link_eef", reach=0.2)])
    space = ConstrainedSpace(constraint, [0.4])
    core = native.core_space(space)
    report = native.compile_report(space)
    assert report["compiled"] == [constraint.parts[1].spec()["type"]] and core.batched and core.g == 1
    assert "where is not recorded" in report["callbacks"][constraint.parts[0].spec()["type"]]
    q = robot.sample_uniform(30, np.random.default_rng(2))
    ys = np.full((30, 1), 0.4)
    F, J = core.jacobian(q)
    F_py, J_py = constraint.jacobian(q, ys)
    np.testing.assert_allclose(F, F_py, rtol=0, atol=AGREE)
    np.testing.assert_allclose(J, J_py, rtol=0, atol=1e-7)  # the callback part's central differences
    np.testing.assert_allclose(core.inequality(q), constraint.inequality(q, ys), rtol=0, atol=AGREE)
    np.testing.assert_allclose(core.violation(q), space.violation(q), rtol=0, atol=AGREE)


def _nan(c, q, y):
    """NaN on every configuration (log of a negative number), through maximum and minimum."""
    xp = array_namespace(q)
    p, _ = c.robot.frame_pose(q, c.a)
    bad = xp.log(p[:, :1] - 10.0)
    return xp.concat([xp.maximum(bad, -1.0), xp.minimum(-1.0, bad), p[:, 1:2]], axis=1)


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
def test_a_nan_residual_stays_nan_compiled(robots):
    """numpy's maximum and minimum keep NaN: so do the compiled ones (the state is then invalid both ways)."""
    constraint = Synthetic(robots["xarm7"], "nan", _nan)
    space = ConstrainedSpace(constraint, [0.4])
    core = native.core_space(space)
    assert not core.batched and native.compile_report(space)["compiled"]
    F = core.residual(robots["xarm7"].sample_uniform(4, np.random.default_rng(0)))
    assert np.isnan(F[:, :2]).all() and np.isfinite(F[:, 2]).all()
