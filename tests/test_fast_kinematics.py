"""The numpy forward kinematics (products of precomputed step transforms, in chunks) equals the torch path and
pinocchio's full model to 1e-12: fixed and floating bases, locked joints, continuous joints, frames no group
joint moves, batches split in chunks; unknown frames are refused as before."""

import numpy as np
import pinocchio as pin
import pytest
import torch

from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot

PR2_ARM = ["torso_lift_joint", "r_shoulder_pan_joint", "r_shoulder_lift_joint", "r_upper_arm_roll_joint",
           "r_elbow_flex_joint", "r_forearm_roll_joint", "r_wrist_flex_joint", "r_wrist_roll_joint"]
# (name, planning group, floating base, frames: one at the end of the group's chain, one elsewhere)
CASES = [
    ("panda", None, False, ["panda_hand_tcp", "panda_link3"]),
    ("xarm7", None, False, ["link_eef", "link1"]),  # the user task's robot
    ("talos", None, True, ["left_sole_link", "gripper_right_base_link"]),  # the base coordinates first
    ("pr2", PR2_ARM, False, ["r_gripper_tool_frame", "l_gripper_tool_frame"]),  # locked left arm, continuous joints
    ("panda", [f"panda_joint{i}" for i in (1, 2, 4)], False, ["panda_hand_tcp", "panda_link0"]),  # locked in the chain
]


@pytest.fixture(scope="module", params=CASES, ids=[f"{c[0]}-{i}" for i, c in enumerate(CASES)])
def case(request):
    name, joints, floating, frames = request.param
    return Robot.load(name, joints, floating_base=floating), frames


def test_frame_pose_equals_the_torch_path_and_pinocchio(case):
    robot, frames = case
    q = robot.sample_uniform(9, np.random.default_rng(1))
    data = robot.model.createData()
    full = robot.to_pinocchio(q)
    for frame in frames:
        p, R = robot.frame_pose(q, frame)
        assert p.shape == (9, 3) and R.shape == (9, 3, 3) and p.dtype == np.float64
        pt, Rt = robot.frame_pose(torch.as_tensor(q), frame)
        np.testing.assert_allclose(p, pt.numpy(), rtol=0, atol=1e-12)
        np.testing.assert_allclose(R, Rt.numpy(), rtol=0, atol=1e-12)
        fid = robot.frame_id(frame)
        for b, row in enumerate(full):
            pin.framesForwardKinematics(robot.model, data, row)
            np.testing.assert_allclose(p[b], data.oMf[fid].translation, rtol=0, atol=1e-12)
            np.testing.assert_allclose(R[b], data.oMf[fid].rotation, rtol=0, atol=1e-12)


def test_com_equals_the_torch_path_and_pinocchio(case):
    robot, _ = case
    q = robot.sample_uniform(5, np.random.default_rng(2))
    com = robot.com(q)
    np.testing.assert_allclose(com, robot.com(torch.as_tensor(q)).numpy(), rtol=0, atol=1e-12)
    data = robot.model.createData()
    for b, row in enumerate(robot.to_pinocchio(q)):
        np.testing.assert_allclose(com[b], pin.centerOfMass(robot.model, data, row), rtol=0, atol=1e-12)
    np.testing.assert_allclose(com, robot.com(q, jacobian=True)[0], rtol=0, atol=1e-12)  # the Jacobian's own path


def test_batches_in_chunks_equal_row_by_row():
    robot = Robot.load("talos", floating_base=True)  # 38 coordinates: com goes in chunks of 2048 // 38 rows
    q = robot.sample_uniform(130, np.random.default_rng(3))
    p, R = robot.frame_pose(q, "left_sole_link")
    com = robot.com(q)
    rows = [robot.frame_pose(row, "left_sole_link") for row in q]  # (n,) rows, promoted to (1, n)
    np.testing.assert_allclose(p, np.concatenate([r[0] for r in rows]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(R, np.concatenate([r[1] for r in rows]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(com, np.concatenate([robot.com(row) for row in q]), rtol=0, atol=1e-12)


def test_a_frame_no_group_joint_moves_is_constant_and_writable():
    robot = Robot.load("panda", ["panda_joint1", "panda_joint2"])
    q = robot.sample_uniform(4, np.random.default_rng(4))
    p, R = robot.frame_pose(q, "panda_link0")
    assert np.ptp(p, axis=0).max() == 0 and np.ptp(R, axis=0).max() == 0
    np.testing.assert_allclose(R[0], np.eye(3), atol=1e-12)
    p[0] += 1.0  # the caller's own copy: the next call is unchanged
    np.testing.assert_allclose(robot.frame_pose(q, "panda_link0")[0], np.zeros((4, 3)), atol=1e-12)


def test_unknown_frames_are_refused_as_before():
    robot = Robot.load("xarm7")
    for _ in range(2):  # nothing is cached for a name that does not exist
        with pytest.raises(ManifoldgenError, match=r"unknown frame 'link_ef' for robot xarm7; did you mean .*link_eef"):
            robot.frame_pose(np.zeros(7), "link_ef")
    with pytest.raises(ManifoldgenError, match=r"expected configurations of shape \(B, 7\), got \(1, 6\)"):
        robot.frame_pose(np.zeros(6), "link_eef")



def test_torch_gradients_equal_the_analytic_jacobians(case):
    """Autograd through the torch step products gives each frame's position Jacobian and the CoM Jacobian of the
    numpy path (what the training penalty's gradient rests on)."""
    robot, frames = case
    q = robot.sample_uniform(4, np.random.default_rng(6))
    w = np.random.default_rng(7).normal(size=(4, 3))
    for frame in [*frames, "com"]:
        qt = torch.as_tensor(q).requires_grad_(True)
        out = robot.com(qt) if frame == "com" else robot.frame_pose(qt, frame)[0]
        J = robot.com(q, jacobian=True)[1] if frame == "com" else robot.frame_jacobian(q, frame)[2][:, :3]
        if not out.requires_grad:  # a frame no group joint moves
            assert not J.any()
            continue
        (out * torch.as_tensor(w)).sum().backward()
        np.testing.assert_allclose(qt.grad.numpy(), np.einsum("bi,bin->bn", w, J), rtol=0, atol=1e-10)


def test_a_penalty_computes_shared_frames_once_with_the_same_value_and_gradient():
    """Within one penalty the residual and the inequality read the feet and the centre of mass once; the value and
    gradient are those of separate evaluations, and a second penalty of the same tensor builds its own graph."""
    from manifoldgen.constraints.base import INEQUALITY_SCALE, as_like
    from manifoldgen.tasks import get_task

    task = get_task("balance", "centauro")
    c, robot = task.constraint, task.robot
    rng = np.random.default_rng(0)
    q = torch.tensor(task.home + 0.05 * rng.standard_normal((8, robot.n)), requires_grad=True)
    y = torch.tensor(np.repeat(task.home_condition[None], 8, axis=0))
    calls = []
    compute = robot.torch_kinematics._frame_pose
    robot.torch_kinematics._frame_pose = lambda q, frame: calls.append(frame) or compute(q, frame)
    try:
        shared = c.penalty(q, y)
        once = len(calls)
        F = c.residual(q, y) / as_like(c.tolerance, q)
        separate = (F * F).sum(dim=1) + (c.inequality(q, y).clamp(min=0) / INEQUALITY_SCALE).pow(2).sum(dim=1)
    finally:
        robot.torch_kinematics._frame_pose = compute
    assert once == len(set(calls[:once])) and len(calls) - once > once  # shared: each frame once; apart: some twice
    (g_shared,) = torch.autograd.grad(shared.sum(), q)
    (g_separate,) = torch.autograd.grad(separate.sum(), q)
    assert torch.allclose(shared, separate, rtol=1e-12) and torch.allclose(g_shared, g_separate, rtol=1e-9)
    for _ in range(2):  # the same leaf again: a graph of its own each time
        c.penalty(q, y).sum().backward()
