"""Constraints: pose residual and Jacobian, SO(3) helpers, composition, conditions, extensibility."""

import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from manifoldgen.constraints import (BalanceConstraint, ClosedChainConstraint, Condition, Constraint, ConstraintSet,
                                     JointLinearConstraint, OrientationConstraint, PlaneConstraint, PoseConstraint,
                                     RotationConstraint, SphereConstraint, array_namespace, build_constraint,
                                     project)
from manifoldgen.robot import Robot
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
    assert spec["position_tolerance"] == 0.01 and spec["orientation_tolerance"] == 0.01
    assert spec["values"] == [[0.2], [0.3], [0.4], [0.5], [0.6], [0.7]]
    assert np.allclose(np.array(spec["rotation"]) @ np.array(spec["rotation"]).T, np.eye(3))
    assert ToolDownAtX(panda_task.robot).spec()["type"] == "test_constraints:ToolDownAtX"


def test_condition_range_warns_or_refuses(panda_task):
    cond = panda_task.condition
    assert cond.low[0] == pytest.approx(0.2) and cond.high[0] == pytest.approx(0.7)
    with pytest.warns(UserWarning, match="outside the trained range"):
        cond.check([[0.9]])
    with pytest.raises(ManifoldgenError, match="outside the trained range"):
        cond.check([[0.9]], strict=True)
    with pytest.warns(UserWarning, match=r"conditions \[0.05\], \[0.1\], \[0.8\] and 1 more are outside"):
        cond.check([[0.9], [0.1], [0.4], [0.05], [0.8], [0.9]])  # each value outside named once, the rest counted
    with pytest.raises(ManifoldgenError, match="needs 1 value"):
        cond.check([[0.3, 0.4]])


class ToolDownAtX(Constraint):
    """A user constraint as the README writes it: residual only (its Jacobian comes from autograd)."""

    def __init__(self, robot, frame="panda_hand_tcp", values=((0.4,), (0.5,)), tolerance=0.01):
        self.robot, self.frame = robot, frame
        self.condition = Condition(("x",), ("m",), np.asarray(values, float))
        self.tolerance = np.full(3, tolerance)

    def residual(self, q, y):
        q, y = self.batch(q, y)
        p, R = self.robot.frame_pose(q, self.frame)
        return array_namespace(q).concat([p[:, :1] - y, R[:, :2, 2]], axis=1)


def test_constraint_set_stacks_residuals_and_splits_conditions(panda_task, rng):
    both = ConstraintSet([panda_task.constraint, ToolDownAtX(panda_task.robot)])
    assert both.m == 7 and both.condition.k == 2 and both.condition.names[1] == "x"
    assert both.condition.grid.shape == (12, 2)  # 6 heights x 2 x values
    q, y = panda_task.robot.sample_uniform(4, rng), np.array([0.45, 0.4])
    F, J = both.jacobian(q, y)
    assert F.shape == (4, 7) and J.shape == (4, 7, 7)
    np.testing.assert_allclose(F[:, :4], panda_task.constraint.residual(q, [0.45]))
    p, _ = panda_task.robot.frame_pose(q, "panda_hand_tcp")
    np.testing.assert_allclose(F[:, 4], p[:, 0] - 0.4)


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


FACING = np.diag([-1.0, -1.0, 1.0])  # two grippers facing each other across a tray
FEET = ["contact_1", "contact_2", "contact_3", "contact_4"]


@pytest.fixture(scope="module")
def pr2_both_arms():
    group = ["torso_lift_joint"] + [f"{s}_{j}" for s in "rl" for j in (
        "shoulder_pan_joint", "shoulder_lift_joint", "upper_arm_roll_joint", "elbow_flex_joint",
        "forearm_roll_joint", "wrist_flex_joint", "wrist_roll_joint")]
    return Robot.load("pr2", group)


@pytest.fixture(scope="module")
def centauro_floating():
    robot = Robot.load("centauro", floating_base=True)
    stance = np.zeros(robot.n)  # the SRDF's homing pose (the reference), base raised until the wheels touch z = 0
    for i, joint in enumerate(robot.joints[6:]):
        stance[6 + i] = robot.reference[robot.model.joints[robot.model.getJointId(joint)].idx_q]
    stance = np.clip(stance, robot.lower, robot.upper)
    stance[2] -= np.mean([robot.frame_pose(stance, f)[0][0, 2] for f in FEET])
    return robot, stance


def _balance(robot, stance):
    return BalanceConstraint(robot, FEET, np.stack([robot.frame_pose(stance, f)[0][0] for f in FEET]), "pelvis",
                             [[0.7], [0.8]])


# every constraint type: (name, factory(panda, pr2, centauro) -> (constraint, seeds (B, n), y (k,)))
CASES = {
    "pose": lambda t, p, c: (t.constraint, None, [0.45]),
    "pose-xy-axes": lambda t, p, c: (PoseConstraint(t.robot, "panda_hand_tcp", t.constraint.rotation, [[0.4, 0.0]],
                                                    position_axes=("x", "y"), orientation_axes=("x", "y")),
                                     None, [0.4, 0.1]),
    "orientation": lambda t, p, c: (OrientationConstraint(t.robot, "panda_hand_tcp", (0, 0, 1), (0, 0, -1)),
                                    None, []),
    "plane": lambda t, p, c: (PlaneConstraint(t.robot, "panda_hand_tcp", [[0, 0, 1]], [[0.3], [0.5]]), None, [0.4]),
    "line": lambda t, p, c: (PlaneConstraint(t.robot, "panda_hand_tcp", [[1, 0, 0], [0, 1, 1]], [[0.4, 0.5]]),
                             None, [0.4, 0.5]),
    "sphere": lambda t, p, c: (SphereConstraint(t.robot, "panda_hand_tcp", [[0.5], [0.7]], center=[0.0, 0.0, 0.3]),
                               None, [0.6]),
    "joint_linear": lambda t, p, c: (JointLinearConstraint(t.robot, [[1, 1, 0, 0, 0, 0, 0]], [[0.0], [0.5]]),
                                     None, [0.3]),
    "closed_chain": lambda t, p, c: (ClosedChainConstraint(p, "r_gripper_tool_frame", "l_gripper_tool_frame",
                                                           FACING, [[0.3], [0.5]]), None, [0.4]),
    "rotation": lambda t, p, c: (RotationConstraint(p, "r_gripper_tool_frame", np.eye(3), [[-0.5], [0.5]]),
                                 None, [0.3]),
    "balance": lambda t, p, c: (_balance(*c), c[1] + 0.1 * np.random.default_rng(1).normal(size=(40, c[0].n)),
                                [0.75]),
    "set": lambda t, p, c: (ConstraintSet([OrientationConstraint(t.robot, "panda_hand_tcp", (0, 0, 1), (0, 0, -1)),
                                           PlaneConstraint(t.robot, "panda_hand_tcp", [[0, 0, 1]], [[0.3], [0.5]])]),
                            None, [0.4]),
    "user": lambda t, p, c: (ToolDownAtX(t.robot), None, [0.45]),
}


@pytest.mark.parametrize("case", list(CASES))
def test_constraint_contract(case, panda_task, pr2_both_arms, centauro_floating, rng):
    """Every type: Jacobian = finite differences, torch residual = numpy residual (and differentiable),
    spec round trip, projection converges onto points that satisfy it."""
    import torch

    c, seeds, y = CASES[case](panda_task, pr2_both_arms, centauro_floating)
    robot = c.robot
    q = robot.sample_uniform(3, rng) if seeds is None else seeds[:3]
    _fd_check(c, q, np.broadcast_to(np.asarray(y, float), (3, len(y))))
    qt = torch.as_tensor(q, dtype=torch.float64).requires_grad_(True)
    Ft = c.residual(qt, torch.tensor(y, dtype=torch.float64))
    np.testing.assert_allclose(Ft.detach().numpy(), c.residual(q, y), atol=1e-9)
    Gt = c.inequality(qt, torch.tensor(y, dtype=torch.float64))
    np.testing.assert_allclose(Gt.detach().numpy(), c.inequality(q, y), atol=1e-9)
    c.penalty(qt, torch.tensor(y, dtype=torch.float64)).sum().backward()
    assert torch.isfinite(qt.grad).all() and qt.grad.abs().sum() > 0
    rebuilt = build_constraint(robot, c.spec())
    assert type(rebuilt) is type(c) and rebuilt.spec() == c.spec()
    np.testing.assert_allclose(rebuilt.residual(q, y), c.residual(q, y))
    res = project(c, robot.sample_uniform(40, rng) if seeds is None else seeds, y)
    assert res.converged.mean() > 0.3
    ok = res.q[res.converged]
    assert c.violation(ok, y).max() < 1e-3 and robot.within_limits(ok).all()
    _core_and_checker_agree(c, q, np.asarray(y, float), built_in=case != "user")


def test_the_core_term_table_is_what_the_built_in_constraints_write(panda_task, pr2_both_arms, centauro_floating):
    """The core's table of built-in terms (native/src/builtin_terms.cpp, ``BUILT_IN_TERMS``) holds exactly the term
    types the built-in constraints write (:meth:`Constraint.core_terms`; the others trace): no table entry without a
    constraint that uses it, no constraint term the table lacks. With the contract test above, adding a built-in constraint is its
    Python file, its C++ term (a struct and its table entry, in one file) and its checker entry."""
    import manifoldgen_core

    from manifoldgen import core_extension, core_terms
    from manifoldgen.space import ConstrainedSpace

    if core_extension.core_problem():
        pytest.skip(core_extension.core_problem())
    written = set()
    for make in CASES.values():
        c, _, y = make(panda_task, pr2_both_arms, centauro_floating)
        types = {term["type"] for term in core_terms.constraint_terms(ConstrainedSpace(c, np.asarray(y, float)))}
        written |= types - {"expression", "expression_inequality"}  # a residual that traces (plane, a user's)
    assert written == set(manifoldgen_core.BUILT_IN_TERMS)


def _core_and_checker_agree(c, q, y, built_in: bool):
    """The compiled core runs the constraint with no Python callback (a built-in through its own core terms,
    :meth:`Constraint.core_terms`, or compiled from its trace) to the same residual and Jacobian; the outside
    checker (examples/recheck.py, pinocchio alone) knows every built-in type, so adding one means its Python
    file, its core term or a residual that traces, and its checker entry."""
    from manifoldgen import core_extension, native
    from manifoldgen.space import ConstrainedSpace

    if core_extension.core_problem():
        return
    space = ConstrainedSpace(c, y)
    core = native.core_space(space)
    assert native.compile_report(space)["callbacks"] == {}
    F, J = core.jacobian(q)
    np.testing.assert_allclose(F, c.residual(q, y), atol=1e-9)
    np.testing.assert_allclose(J, c.jacobian(q, y)[1], atol=1e-6)
    if built_in:
        sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
        try:
            import recheck
        finally:
            sys.path.pop(0)
        parts = [c] if not isinstance(c, ConstraintSet) else c.parts
        assert all(part.spec()["type"] in recheck.PART_TYPES for part in parts)


def test_closed_chain_between_pr2_grippers(pr2_both_arms, rng):
    robot, facing = pr2_both_arms, FACING
    c = ClosedChainConstraint(robot, "r_gripper_tool_frame", "l_gripper_tool_frame", facing, [[0.3], [0.5]])
    res = project(c, robot.sample_uniform(200, rng), [0.4])
    ok = res.q[res.converged]
    assert len(ok) > 50 and c.satisfied(ok, [0.4]).all()
    pa, Ra = robot.frame_pose(ok, "r_gripper_tool_frame")
    pb, Rb = robot.frame_pose(ok, "l_gripper_tool_frame")
    np.testing.assert_allclose(np.linalg.norm(pb - pa, axis=1), 0.4, atol=1e-5)
    np.testing.assert_allclose(np.transpose(Ra, (0, 2, 1)) @ Rb, np.broadcast_to(facing, Ra.shape), atol=1e-5)


def test_balance_on_centauro_with_floating_base(centauro_floating, rng):
    robot, stance = centauro_floating
    c = _balance(robot, stance)
    assert c.satisfied(stance, [stance[2]])[0] and np.all(c.inequality(stance, [stance[2]]) < 0)
    res = project(c, np.clip(stance + 0.2 * rng.normal(size=(100, robot.n)), robot.lower, robot.upper), [0.75])
    assert res.converged.mean() > 0.9
    moved = res.q[res.converged]
    shifted = moved.copy()
    shifted[:, 0] += 1.0  # slide the base 1 m forward with the legs unchanged: feet leave their spots
    assert not c.satisfied(shifted, [0.75]).any()
    G = c.inequality(moved, [0.75])
    assert np.array_equal(c.satisfied(moved, [0.75]), np.all(G <= 0, axis=1) & robot.within_limits(moved))


def test_joint_linear_refuses_a_row_too_short_to_move_its_residual(panda_task):
    """A coefficient row of norm 1e-300 is as good as zero: refused when the constraint is built, not after
    collect's batches fail."""
    with pytest.raises(ManifoldgenError, match=r"none all zero \(a norm under 1e-09\); got shape \(1, 7\)"):
        JointLinearConstraint(panda_task.robot, [[0.0] * 6 + [1e-300]], [[0.0]])
    with pytest.raises(ManifoldgenError, match=r"joint_linear row 0 constrains nothing: over the joint limits its "
                                               r"A q spans only 5.79e-08, within twice the tolerance 0.01"):
        JointLinearConstraint(panda_task.robot, [[0.0] * 6 + [1e-8]], [[0.0]])  # every q is within tolerance
    assert JointLinearConstraint(panda_task.robot, [[0.0] * 6 + [1e-1]], [[0.0]]).coefficients.shape == (1, 7)
