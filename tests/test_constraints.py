"""Constraints: pose residual and Jacobian, SO(3) helpers, composition, conditions, extensibility."""

import numpy as np
import pinocchio as pin
import pytest

from manifoldgen.constraints import Condition, Constraint, ConstraintSet, PoseConstraint
from manifoldgen.constraints.so3 import jlog3, log3
from manifoldgen.errors import ManifoldgenError


def random_rotations(rng, count):
    return np.array([pin.exp3(w) for w in rng.normal(size=(count, 3)) * 1.2])


def test_log3_matches_pinocchio_including_near_pi(rng):
    R = random_rotations(rng, 50)
    near_pi = np.array([pin.exp3(np.pi * (1 - 1e-7) * a / np.linalg.norm(a)) for a in rng.normal(size=(5, 3))])
    R = np.concatenate([R, near_pi, np.eye(3)[None]])
    expected = np.array([pin.log3(r) for r in R])
    np.testing.assert_allclose(log3(R), expected, atol=1e-6)


def test_jlog3_matches_pinocchio(rng):
    R = random_rotations(rng, 20)
    np.testing.assert_allclose(jlog3(log3(R)), np.array([pin.Jlog3(r) for r in R]), atol=1e-9)


def test_pose_constraint_residual_is_zero_at_home_and_jacobian_matches_fd(panda_task, rng):
    c = panda_task.constraint
    assert np.abs(c.residual(panda_task.home, panda_task.home_condition)).max() < 1e-6
    q, y = panda_task.robot.sample_uniform(5, rng), np.full((5, 1), 0.45)
    F, J = c.jacobian(q, y)
    np.testing.assert_allclose(F, c.residual(q, y))
    eps = 1e-6
    for i in range(7):
        dq = np.zeros(7)
        dq[i] = eps
        np.testing.assert_allclose(J[:, :, i], (c.residual(q + dq, y) - c.residual(q - dq, y)) / (2 * eps), atol=1e-5)


def test_pose_residual_measures_height_and_orientation(panda_task):
    c, home = panda_task.constraint, panda_task.home
    F = c.residual(home, [0.40])
    assert F[0, 0] == pytest.approx(0.05, abs=1e-6)  # home is at 0.45 m
    assert not c.satisfied(home, [0.40])[0] and c.satisfied(home, [0.455])[0]
    tilted = home.copy()
    tilted[6] += 0.02  # the last joint spins the gripper about its axis: yaw error 0.02 rad
    assert np.abs(c.residual(tilted, [0.45])[0, 1:]).max() == pytest.approx(0.02, abs=1e-6)
    assert not c.satisfied(tilted, [0.45])[0]


def test_spec_is_complete(panda_task):
    spec = panda_task.constraint.spec()
    assert spec["type"] == "pose" and spec["frame"] == "panda_hand_tcp" and spec["position_axes"] == ["z"]
    assert spec["tolerance"] == {"position": 0.01, "orientation": 0.01}
    assert np.allclose(np.array(spec["rotation"]) @ np.array(spec["rotation"]).T, np.eye(3))


def test_condition_range_warns_or_refuses(panda_task):
    cond = panda_task.condition
    assert cond.low[0] == pytest.approx(0.2) and cond.high[0] == pytest.approx(0.7)
    with pytest.warns(UserWarning, match="outside the trained range"):
        cond.check([[0.9]])
    with pytest.raises(ManifoldgenError, match="outside the trained range"):
        cond.check([[0.9]], strict=True)
    with pytest.raises(ManifoldgenError, match="needs 1 value"):
        cond.check([[0.3, 0.4]])


class JointSum(Constraint):
    """A user constraint in a few lines: q0 + q1 = y (a linear manifold with a known projection)."""

    def __init__(self, robot):
        self.robot, self.tolerance = robot, np.array([1e-3])
        self.condition = Condition(("sum",), ("rad",), np.array([[0.0], [0.5]]))

    def residual(self, q, y):
        q, y = self.batch(q, y)
        return q[:, :1] + q[:, 1:2] - y

    def jacobian(self, q, y):
        q, y = self.batch(q, y)
        J = np.zeros((len(q), 1, self.robot.n))
        J[:, 0, :2] = 1.0
        return self.residual(q, y), J

    def spec(self):
        return {"type": "joint_sum"}


def test_constraint_set_stacks_residuals_and_splits_conditions(panda_task, rng):
    both = ConstraintSet([panda_task.constraint, JointSum(panda_task.robot)])
    assert both.m == 5 and both.condition.k == 2 and both.condition.names[1] == "sum"
    q, y = panda_task.robot.sample_uniform(4, rng), np.array([0.45, 0.1])
    F, J = both.jacobian(q, y)
    assert F.shape == (4, 5) and J.shape == (4, 5, 7)
    np.testing.assert_allclose(F[:, :4], panda_task.constraint.residual(q, [0.45]))
    np.testing.assert_allclose(F[:, 4], q[:, 0] + q[:, 1] - 0.1)


def test_pose_constraint_rejects_bad_specification(panda_task):
    with pytest.raises(ManifoldgenError, match="rotation matrix"):
        PoseConstraint(panda_task.robot, "panda_hand_tcp", np.ones((3, 3)), [[0.3]])
    with pytest.raises(ManifoldgenError, match="unknown frame"):
        PoseConstraint(panda_task.robot, "gripper", np.eye(3), [[0.3]])


def _fd_check(constraint, q, y, eps=1e-6, atol=1e-5):
    F, J = constraint.jacobian(q, y)
    for i in range(q.shape[1]):
        dq = np.zeros(q.shape[1])
        dq[i] = eps
        fd = (constraint.residual(q + dq, y) - constraint.residual(q - dq, y)) / (2 * eps)
        np.testing.assert_allclose(J[:, :, i], fd, atol=atol)


def test_closed_chain_between_pr2_grippers(rng):
    from manifoldgen.constraints import project
    from manifoldgen.constraints.closed_chain import ClosedChainConstraint
    from manifoldgen.robot import Robot
    from manifoldgen.tasks.pose import PR2_GROUP

    joints = PR2_GROUP + [j.replace("r_", "l_", 1) for j in PR2_GROUP[1:]]
    robot = Robot.load("pr2", joints)
    facing = np.diag([-1.0, -1.0, 1.0])  # the grippers face each other across a tray
    c = ClosedChainConstraint(robot, "r_gripper_tool_frame", "l_gripper_tool_frame", facing, [[0.3], [0.5]])
    _fd_check(c, robot.sample_uniform(3, rng), np.full((3, 1), 0.4))
    res = project(c, robot.sample_uniform(200, rng), [0.4])
    ok = res.q[res.converged]
    assert len(ok) > 50 and c.satisfied(ok, [0.4]).all()
    pa, Ra = robot.frame_pose(ok, "r_gripper_tool_frame")
    pb, Rb = robot.frame_pose(ok, "l_gripper_tool_frame")
    np.testing.assert_allclose(np.linalg.norm(pb - pa, axis=1), 0.4, atol=1e-5)
    np.testing.assert_allclose(np.transpose(Ra, (0, 2, 1)) @ Rb, np.broadcast_to(facing, Ra.shape), atol=1e-5)


def test_balance_on_centauro_with_floating_base(rng):
    from manifoldgen.constraints import project
    from manifoldgen.constraints.balance import BalanceConstraint
    from manifoldgen.robot import Robot

    robot = Robot.load("centauro", floating_base=True)
    feet = ["wheel_1", "wheel_2", "wheel_3", "wheel_4"]
    stance = np.clip(np.zeros(robot.n), robot.lower, robot.upper)
    stance[2] = 0.7
    c = BalanceConstraint(robot, feet, np.stack([robot.frame_pose(stance, f)[0][0] for f in feet]),
                          "pelvis", [[0.6], [0.7]])
    assert c.satisfied(stance, [0.7])[0] and np.all(c.inequality(stance, [0.7]) < 0)
    _fd_check(c, stance + 0.05 * rng.normal(size=(2, robot.n)), np.full((2, 1), 0.65))
    res = project(c, np.clip(stance + 0.2 * rng.normal(size=(100, robot.n)), robot.lower, robot.upper), [0.65])
    assert res.converged.mean() > 0.9
    moved = res.q[res.converged]
    shifted = moved.copy()
    shifted[:, 0] += 1.0  # slide the base 1 m forward with the legs unchanged: feet leave their spots
    assert not c.satisfied(shifted, [0.65]).any()
    G = c.inequality(moved, [0.65])
    assert np.array_equal(c.satisfied(moved, [0.65]), np.all(G <= 0, axis=1) & robot.within_limits(moved))
