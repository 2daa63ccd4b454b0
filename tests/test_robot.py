"""Robot: batched FK, Jacobians and CoM against pinocchio and finite differences; bad input."""

import numpy as np
import pinocchio as pin
import pytest

from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot
from manifoldgen.tasks.pose import CENTAURO_GROUP, PANDA_ARM, PR2_GROUP

CASES = [("panda", PANDA_ARM, "panda_hand_tcp", False),
         ("pr2", PR2_GROUP, "r_gripper_tool_frame", False),  # continuous joints (nq = 2 in pinocchio)
         ("centauro", CENTAURO_GROUP, "arm1_8", True)]  # unaligned axes, floating base


@pytest.fixture(scope="module", params=CASES, ids=[c[0] for c in CASES])
def case(request):
    name, joints, frame, floating = request.param
    return Robot.load(name, joints, floating_base=floating), frame


def test_forward_kinematics_and_com_match_pinocchio_on_the_full_model(case, rng):
    robot, frame = case
    q = robot.sample_uniform(20, rng)
    p, R = robot.frame_pose(q, frame)
    com = robot.com(q)
    data, fid = robot.model.createData(), robot.model.getFrameId(frame)
    for b, full in enumerate(robot.to_pinocchio(q)):
        pin.framesForwardKinematics(robot.model, data, full)
        np.testing.assert_allclose(p[b], data.oMf[fid].translation, atol=1e-12)
        np.testing.assert_allclose(R[b], data.oMf[fid].rotation, atol=1e-12)
        np.testing.assert_allclose(com[b], pin.centerOfMass(robot.model, data, full), atol=1e-12)


def test_jacobians_match_finite_differences(case, rng):
    robot, frame = case
    q = robot.sample_uniform(4, rng)
    _, _, J = robot.frame_jacobian(q, frame)
    _, Jc = robot.com(q, jacobian=True)
    eps = 1e-6
    for i in range(robot.n):
        dq = np.zeros(robot.n)
        dq[i] = eps
        (p1, R1), (p0, R0) = robot.frame_pose(q + dq, frame), robot.frame_pose(q - dq, frame)
        omega = np.array([pin.log3(a @ b.T) for a, b in zip(R1, R0)]) / (2 * eps)
        np.testing.assert_allclose(J[:, :3, i], (p1 - p0) / (2 * eps), atol=1e-6)
        np.testing.assert_allclose(J[:, 3:, i], omega, atol=1e-6)
        np.testing.assert_allclose(Jc[:, :, i], (robot.com(q + dq) - robot.com(q - dq)) / (2 * eps), atol=1e-6)


def test_jacobian_matches_pinocchio_world_aligned_jacobian(rng):
    robot = Robot.load("panda", PANDA_ARM)
    q = robot.sample_uniform(3, rng)
    _, _, J = robot.frame_jacobian(q, "panda_hand_tcp")
    data, fid = robot.model.createData(), robot.model.getFrameId("panda_hand_tcp")
    for b, full in enumerate(robot.to_pinocchio(q)):
        Jp = pin.computeFrameJacobian(robot.model, data, full, fid, pin.LOCAL_WORLD_ALIGNED)
        np.testing.assert_allclose(J[b], Jp[:, :7], atol=1e-12)


def test_planning_group_limits_and_locked_joints():
    robot = Robot.load("pr2", PR2_GROUP)
    assert robot.n == 8 and robot.joints == PR2_GROUP
    assert np.all(robot.lower < robot.upper) and np.all(np.isfinite(robot.lower))
    assert robot.lower[5] == -np.pi and robot.upper[5] == np.pi  # continuous forearm roll: one turn
    assert "l_shoulder_pan_joint" in robot.locked and "torso_lift_joint" not in robot.locked
    floating = Robot.load("panda", PANDA_ARM, floating_base=True)
    assert floating.n == 13 and np.all(np.isfinite(floating.lower)) and np.all(np.isfinite(floating.upper))


def test_srdf_group_state_is_the_default_reference():
    robot = Robot.load("panda", ["panda_joint1"])
    assert robot.locked["panda_joint4"] == pytest.approx(-2.35619)


@pytest.mark.parametrize("kwargs, message", [
    (dict(robot="not_a_robot"), "unknown robot 'not_a_robot'"),
    (dict(robot="/no/such/file.urdf"), "URDF file not found"),
    (dict(robot="panda", joints=["panda_joint99"]), "unknown joint 'panda_joint99'"),
])
def test_bad_robot_input_is_named(kwargs, message):
    with pytest.raises(ManifoldgenError, match=message):
        Robot.load(**kwargs)


def test_unparsable_urdf_is_reported(tmp_path):
    bad = tmp_path / "broken.urdf"
    bad.write_text("<robot name='x'><link name='a'></robot")
    with pytest.raises(ManifoldgenError, match="cannot parse URDF"):
        Robot.load(str(bad))


def test_unknown_frame_and_bad_shapes():
    robot = Robot.load("panda", PANDA_ARM)
    with pytest.raises(ManifoldgenError, match="unknown frame 'panda_hand_tpc'.*panda_hand_tcp"):
        robot.frame_pose(np.zeros(7), "panda_hand_tpc")
    with pytest.raises(ManifoldgenError, match=r"shape \(B, 7\)"):
        robot.frame_pose(np.zeros(6), "panda_hand")
