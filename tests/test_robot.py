"""Robot: batched FK, Jacobians and CoM against pinocchio and finite differences; every
example-robot-data robot by name; URDF + SRDF paths and content identity; bad input."""

import shutil
import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest

from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot, find_robot, known_robots, resolve_robot

PANDA_ARM = [f"panda_joint{i}" for i in range(1, 8)]
PR2_GROUP = ["torso_lift_joint", "r_shoulder_pan_joint", "r_shoulder_lift_joint", "r_upper_arm_roll_joint",
             "r_elbow_flex_joint", "r_forearm_roll_joint", "r_wrist_flex_joint", "r_wrist_roll_joint"]
CENTAURO_GROUP = ["torso_yaw"] + [f"j_arm1_{i}" for i in range(1, 7)]

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


def test_an_srdf_suffix_in_capitals_is_an_srdf(tmp_path):
    """P.SRDF reads as P.srdf does: the same group state becomes the reference."""
    shutil.copy(resolve_robot("panda")[1], tmp_path / "P.SRDF")
    robot = Robot.load("panda", ["panda_joint1"], srdf=tmp_path / "P.SRDF")
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


@pytest.mark.parametrize("text, detail", [
    ("<bad/>", "root element is <bad>"),
    ("<robot name='x'><link name='a'/><joint name='j' type='revolute'><parent link='a'/><child link='b'/>"
     "</joint></robot>", "does not specify limits"),
])
def test_urdf_parser_errors_become_our_one_line(tmp_path, text, detail):
    """What urdfdom prints on file descriptor 2 ends up in our one line, not before it."""
    bad = tmp_path / "bad.urdf"
    bad.write_text(text)
    script = "from manifoldgen.cli import app; app()"
    done = subprocess.run([sys.executable, "-c", script, "robots", str(bad)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2
    lines = (done.stdout + done.stderr).strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: cannot parse URDF") and detail in lines[0], lines


def test_unknown_frame_and_bad_shapes():
    robot = Robot.load("panda", PANDA_ARM)
    with pytest.raises(ManifoldgenError, match="unknown frame 'panda_hand_tpc'.*panda_hand_tcp"):
        robot.frame_pose(np.zeros(7), "panda_hand_tpc")
    with pytest.raises(ManifoldgenError, match=r"shape \(B, 7\)"):
        robot.frame_pose(np.zeros(6), "panda_hand")


# ---------------------------------------------------------------- every robot by name
# ur_description ships SRDFs only for ur3_gripper, ur5, ur5_gripper and ur5_joint_limited_robot.
NO_SRDF_IN_ITS_FOLDER = {"ur3", "ur3_robot", "ur3_joint_limited", "ur3_joint_limited_robot",
                         "ur10", "ur10_robot", "ur10_joint_limited", "ur10_joint_limited_robot"}


@pytest.mark.slow
@pytest.mark.parametrize("name", known_robots())
def test_every_known_robot_loads_by_name(name, rng):
    robot = Robot.load(name)
    assert robot.n > 0 and robot.joints and robot.name == robot.source == name
    folder = robot.urdf_path.parent.parent
    if (folder / "srdf").is_dir() and name not in NO_SRDF_IN_ITS_FOLDER:
        assert robot.srdf is not None and robot.srdf.parent == folder / "srdf"
        assert robot.identity["srdf_sha256"]
    frame = robot.model.frames[-1].name
    q = robot.sample_uniform(1, rng)
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.to_pinocchio(q)[0])
    np.testing.assert_allclose(robot.frame_pose(q, frame)[0][0], data.oMf[robot.frame_id(frame)].translation,
                               atol=1e-9)


def test_the_usual_names_map_to_their_files():
    for name in ["ur5", "xarm7", "kinova", "tiago", "tiago_pro", "talos", "g1", "go1", "go2", "panda", "pr2",
                 "baxter", "centauro", "solo", "solo12", "anymal_b", "hyq", "romeo", "icub", "z1", "so_arm"]:
        assert name in known_robots()
    expected = {"ur5": ("ur5_robot.urdf", "ur5.srdf"), "ur3": ("ur3_robot.urdf", None),
                "talos": ("talos_reduced.urdf", "talos.srdf"), "solo12": ("solo12.urdf", "solo.srdf"),
                "baxter": ("baxter.urdf", "baxter_manipulation.srdf"), "hyq": ("hyq_no_sensors.urdf", "hyq.srdf"),
                "anymal_kinova": ("anymal-kinova.urdf", "anymal-kinova.srdf"), "so_arm": ("so101.urdf", None),
                "g1": ("g1_29dof_rev_1_0.urdf", None), "tiago": ("tiago.urdf", None)}
    for name, (urdf, srdf) in expected.items():
        got_urdf, got_srdf = resolve_robot(name)
        assert (got_urdf.name, got_srdf.name if got_srdf else None) == (urdf, srdf), name
    assert resolve_robot("anymal_c")[0].parent.parent.name == "anymal_c_simple_description"
    assert resolve_robot("anymal")[0] == resolve_robot("anymal_b")[0]
    assert not {"hector", "quadrotor_base", "iris_simple"} & set(known_robots())  # bodies without joints


def test_unknown_robot_name_suggests_close_ones():
    with pytest.raises(ManifoldgenError, match=r"unknown robot 'talso' \(did you mean .*talos"):
        Robot.load("talso")


# ---------------------------------------------------------------- URDF paths, SRDF, identity
@pytest.fixture
def panda_copy(tmp_path):
    """A copy of panda's URDF in a folder of its own, without an SRDF beside it."""
    urdf = tmp_path / "copy" / "my_panda.urdf"
    urdf.parent.mkdir()
    urdf.write_bytes(resolve_robot("panda")[0].read_bytes())
    return urdf


def test_urdf_path_with_explicit_or_neighbouring_srdf(panda_copy):
    srdf = resolve_robot("panda")[1]
    bare = Robot.load(str(panda_copy), ["panda_joint1"])
    assert bare.srdf is None and "srdf_sha256" not in bare.identity
    assert bare.name == "my_panda" and bare.source == str(panda_copy) and bare.urdf_path == panda_copy
    assert bare.locked["panda_joint4"] == 0.0  # neutral: no SRDF group state
    explicit = Robot.load(panda_copy, ["panda_joint1"], srdf=srdf)
    assert explicit.srdf == srdf and explicit.locked["panda_joint4"] == pytest.approx(-2.35619)
    assert explicit.identity == {**Robot.load("panda", ["panda_joint1"]).identity, "name": "my_panda"}
    panda_copy.with_suffix(".srdf").write_bytes(srdf.read_bytes())
    assert Robot.load(str(panda_copy), ["panda_joint1"]).srdf == panda_copy.with_suffix(".srdf")
    with pytest.raises(ManifoldgenError, match="SRDF file not found: .*nothing.srdf; give an existing"):
        Robot.load(str(panda_copy), srdf=panda_copy.parent / "nothing.srdf")


def test_find_robot_compares_file_contents_not_paths(panda_copy, tmp_path):
    assert find_robot(Robot.load("ur5").identity) == "ur5"
    copied_ur5 = tmp_path / "a" / "ur5.urdf"  # an exact copy of example-robot-data's ur5 is ur5
    copied_ur5.parent.mkdir()
    copied_ur5.write_bytes(resolve_robot("ur5")[0].read_bytes())
    assert find_robot(Robot.load(str(copied_ur5)).identity) == "ur5"
    edited = tmp_path / "b" / "ur5.urdf"  # an edited ur5 is found only at a path with the same content
    edited.parent.mkdir()
    edited.write_bytes(copied_ur5.read_bytes() + b"<!-- edited -->\n")
    identity = Robot.load(str(edited)).identity
    moved = tmp_path / "c" / "renamed.urdf"
    moved.parent.mkdir()
    moved.write_bytes(edited.read_bytes())
    assert find_robot(identity, hint=str(moved)) == str(moved)
    with pytest.raises(ManifoldgenError, match=r"no URDF with sha256 \w{12} \(robot 'ur5'\): ur5 has \w{12}; "
                                               r".*pass the path of the URDF"):
        find_robot(identity, hint=str(copied_ur5))
    mine = Robot.load(str(panda_copy)).identity
    assert find_robot(mine, hint=str(panda_copy)) == str(panda_copy)
    with pytest.raises(ManifoldgenError, match="'my_panda' is not an example-robot-data robot; pass the path"):
        find_robot(mine)


# ---------------------------------------------------------------- planning-group validation
TWO_JOINTS = """<robot name="two"><link name="a"/><link name="b"/><link name="c"/>
<joint name="slide" type="planar"><parent link="a"/><child link="b"/></joint>
<joint name="hinge" type="revolute"><parent link="b"/><child link="c"/><axis xyz="0 0 1"/>
<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>"""
NO_JOINT = """<robot name="rigid"><link name="a"/><link name="b"/>
<joint name="weld" type="fixed"><parent link="a"/><child link="b"/></joint></robot>"""


@pytest.mark.parametrize("joints, message", [
    (["panda_joint1", "panda_finger_joint2"],
     "joint 'panda_finger_joint2' of robot panda mimics 'panda_finger_joint1' and cannot move on its own; remove"),
    (["panda_joint1", "panda_joint8"], "joint 'panda_joint8' of robot panda is fixed and cannot move; remove"),
    (["panda_hand_joint"], "joint 'panda_hand_joint' of robot panda is fixed"),
    (["panda_joint1", "panda_joint2", "panda_joint1"], "joint 'panda_joint1' is 2 times in the planning group"),
    ([], "empty planning group for robot panda; name at least one joint"),
    (["base_x", "panda_joint1"], "joint 'base_x' is a floating-base coordinate .* floating_base=True"),
])
def test_bad_planning_group_is_refused_with_the_joint_and_the_fix(joints, message):
    with pytest.raises(ManifoldgenError, match=message):
        Robot.load("panda", joints)


def test_default_group_leaves_out_mimic_and_multi_axis_joints(tmp_path):
    assert "panda_finger_joint1" in Robot.load("panda").joints
    assert "panda_finger_joint2" not in Robot.load("panda").joints
    urdf = tmp_path / "two.urdf"
    urdf.write_text(TWO_JOINTS)
    assert Robot.load(str(urdf)).joints == ["hinge"]
    with pytest.raises(ManifoldgenError, match="joint 'slide' of robot two is a Planar joint, which cannot be in"):
        Robot.load(str(urdf), ["slide"])


def test_robot_without_joints_needs_a_floating_base(tmp_path):
    urdf = tmp_path / "rigid.urdf"
    urdf.write_text(NO_JOINT)
    with pytest.raises(ManifoldgenError, match="robot rigid has no movable joint; load it with floating_base=True"):
        Robot.load(str(urdf))
    assert Robot.load(str(urdf), floating_base=True).n == 6
    assert Robot.load("panda", [], floating_base=True).n == 6  # the base alone is a group
