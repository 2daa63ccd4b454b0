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
