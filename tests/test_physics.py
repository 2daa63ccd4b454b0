"""Physics check: a statically balanced centauro path stays upright in MuJoCo, an unbalanced one falls."""

import json
import sys

import numpy as np
import pytest
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.constraints.base import ConstraintSet
from manifoldgen.constraints.joint_linear import JointLinearConstraint
from manifoldgen.constraints.projection import project
from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import save_npz
from manifoldgen.physics import PhysicsSettings, check_path, check_path_file, summary
from manifoldgen.query import PATH_FORMAT_VERSION
from manifoldgen.tasks import load_task_file

pytestmark = pytest.mark.slow  # the quick loop (pytest -m "not slow") leaves this module out

pytest.importorskip("mujoco")

FEET = ["wheel_1", "wheel_2", "wheel_3", "wheel_4"]
LEGS = [f"{j}_{i}" for i in range(1, 5) for j in ("hip_yaw", "hip_pitch", "knee_pitch", "ankle_pitch")]
# centauro's SRDF stance with the front legs turned inwards (hip yaw 1 by -1, 2 by +1): the front wheels stand
# 0.115 m ahead of the pelvis, the centre of mass 0.04 m ahead: inside the support polygon by 0.076 m
HOME = [0.0, 0.0, 0.687, 0.0, 0.0, 0.0,
        -1.746874, -1.25409, -1.55576, -0.301666, 1.746874, 1.25409, 1.55576, 0.301666,
        0.746874, 1.25409, 1.55576, 0.301667, -0.746874, -1.25409, -1.55576, -0.301667]
FAST = PhysicsSettings(settle_s=0.2, hold_s=0.5, seconds_per_rad=1.0, seconds_per_m=5.0)  # twice the default pace


@pytest.fixture(scope="module")
def balance_task(tmp_path_factory):
    """A balance task file for centauro (floating base + 16 leg joints), feet where HOME puts them."""
    from manifoldgen.robot import Robot

    robot = Robot.load("centauro", LEGS, floating_base=True)
    feet = [robot.frame_pose(np.array(HOME), f)[0][0].tolist() for f in FEET]
    text = f"""name = "balance-test"
robot = "centauro"
floating_base = true
base_bounds = [[-0.5, -0.5, 0.4], [0.5, 0.5, 1.0]]
group = {json.dumps(["base_x", "base_y", "base_z", "base_yaw", "base_pitch", "base_roll", *LEGS])}
home = {json.dumps(HOME)}
home_condition = [0.687]
[[constraints]]
type = "balance"
feet = {json.dumps(FEET)}
foot_positions = {json.dumps(feet)}
base_frame = "pelvis"
values = [[0.62], [0.687]]
margin = 0.02
"""
    file = tmp_path_factory.mktemp("physics") / "balance.toml"
    file.write_text(text)
    return load_task_file(file)


def _save(task, folder, name, waypoints):
    file = folder / f"{name}.npz"
    meta = {**task.meta(), "kind": "path", "format_version": PATH_FORMAT_VERSION, "condition": [0.62]}
    save_npz(file, meta, path=np.asarray(waypoints))
    return file


def _shift_base(task, x_end, z_end, level, count=7, pitch_end=0.0):
    """(count, n): the task's home with the base moved to x_end, z_end in steps, the feet kept where they stand (each
    state projected onto the balance equalities, base_x = x and, when ``level``, base_pitch = 0 (or stepping to
    ``pitch_end``), from the last)."""
    rows = [0, 4] if level else [0]
    fixed = np.eye(task.robot.n)[rows]
    feet_and_base = ConstraintSet([task.constraint, JointLinearConstraint(task.robot, fixed, [[0.0] * len(rows)])])
    states = [task.home]
    for x, z, pitch in zip(np.linspace(0.0, x_end, count)[1:], np.linspace(0.687, z_end, count)[1:],
                           np.linspace(0.0, pitch_end, count)[1:]):
        res = project(feet_and_base, states[-1], [z, x, pitch][:1 + len(rows)])
        assert res.converged[0]
        states.append(res.q[0])
    return np.array(states)


@pytest.fixture(scope="module")
def paths(balance_task, tmp_path_factory):
    """name -> path file: "balanced" moves the base 8 cm back and 3.7 cm down, level (every state satisfies the
    balance constraint, CoM margin included); "unbalanced" pushes the base 0.3 m forward, feet kept, CoM far out.
    (The base stays level in the balanced path: centauro's wheels are locked and the constraint fixes the wheel
    centres only, so pitching a leg rolls its wheel, which the check counts as foot slip: see docs/physics.md.)"""
    task, folder = balance_task, tmp_path_factory.mktemp("paths")
    c = task.constraint
    balanced = _shift_base(task, -0.08, 0.65, level=True)
    assert c.satisfied(balanced, np.linspace(0.687, 0.65, len(balanced))[:, None]).all()
    unbalanced = _shift_base(task, 0.3, 0.687, level=False)
    assert np.abs(c.residual(unbalanced, [0.687])).max() < 1e-5  # feet kept where they stand ...
    assert c.inequality(unbalanced[-1], [0.687]).max() > 0.15  # ... and the CoM 0.15 m beyond the margin
    return {"balanced": _save(task, folder, "balanced", balanced),
            "unbalanced": _save(task, folder, "unbalanced", unbalanced)}


def test_a_balanced_path_stays_upright(paths):
    result = check_path_file(paths["balanced"], FAST)
    assert result.upright and result.stable and not result.fell
    assert result.max_tilt_deg < 1.0 and result.max_slip_m < 0.015 and result.base_drift_m < 0.02
    assert result.max_tracking_error_rad < 0.03  # the servos held the path
    assert max(result.start_foot_gap_m.values()) < 1e-3  # all four wheels on the ground at the start
    assert result.engine["mass_kg"] == pytest.approx(result.engine["pinocchio_mass_kg"])
    assert result.engine["model_error_m"] < 1e-6  # MuJoCo and pinocchio put the feet and CoM at the same place
    assert result.simulated_s > FAST.settle_s + FAST.hold_s
    assert json.loads(json.dumps(result.to_dict()))["settings"]["tilt_threshold_deg"] == 10.0
    again = check_path_file(paths["balanced"], FAST)  # deterministic: the same numbers again
    assert (again.max_tilt_deg, again.foot_slip_m, again.base_drift_m) == (result.max_tilt_deg, result.foot_slip_m,
                                                                          result.base_drift_m)


def test_an_unbalanced_path_falls(paths):
    result = check_path_file(paths["unbalanced"], FAST)
    assert result.fell and not result.upright and not result.stable
    assert result.max_tilt_deg > FAST.fall_tilt_deg or result.base_drift_m > FAST.fall_drop_m


def test_cli_reports_and_writes_json(paths, tmp_path):
    out = tmp_path / "report.json"
    result = CliRunner().invoke(app, ["physics", str(paths["balanced"]), "--hold", "0.3", "--settle", "0.1",
                                      "--duration-scale", "0.5", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "upright" in result.output and "foot slip" in result.output
    report = json.loads(out.read_text())
    assert report["upright"] and report["settings"]["hold_s"] == 0.3


def test_bad_inputs_are_one_line(paths, balance_task, panda_task, tmp_path):
    runner = CliRunner()
    fixed = runner.invoke(app, ["physics", str(_save(panda_task, tmp_path, "panda", [panda_task.home]))])
    assert fixed.exit_code != 0 and "floating-base" in fixed.output
    lifted = balance_task.home.copy()
    lifted[balance_task.robot.joints.index("hip_pitch_1")] -= 0.3  # front-left wheel 9 cm off the ground
    result = runner.invoke(app, ["physics", str(_save(balance_task, tmp_path, "lifted", [lifted])), "--hold", "0"])
    assert result.exit_code == 0 and "wheel_1 does not touch the ground" in result.output
    no_feet = _save(balance_task, tmp_path, "nofeet", [balance_task.home])
    with pytest.raises(ManifoldgenError, match="unknown frame"):
        check_path_file(no_feet, FAST, feet=["nope"])
    with pytest.raises(ManifoldgenError, match="must be a positive number"):
        PhysicsSettings(timestep=0.0)
    missing = runner.invoke(app, ["physics", str(tmp_path / "absent.npz")])
    assert missing.exit_code != 0 and "not found" in missing.output


def test_missing_engine_is_one_line(paths, monkeypatch):
    monkeypatch.setitem(sys.modules, "mujoco", None)  # import mujoco now raises ImportError
    with pytest.raises(ManifoldgenError, match=r"the physics check needs the \[physics\] extra: "
                                               r"pip install 'manifoldgen\[physics\]'"):
        check_path_file(paths["balanced"], FAST)


def test_talos_loads_and_stands():
    """MuJoCo reads talos's URDF and meshes; standing in its SRDF stance on its two soles, it stays put."""
    from manifoldgen.robot import Robot

    robot = Robot.load("talos", floating_base=True)
    stance = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0] +
                      [robot.reference[robot.model.joints[robot.model.getJointId(j)].idx_q] for j in robot.joints[6:]])
    result = check_path(robot, stance[None], ["left_sole_link", "right_sole_link"],
                        PhysicsSettings(settle_s=0.5, hold_s=0.0))
    assert result.upright and result.max_tilt_deg < 1.0 and result.max_slip_m < 0.005
    assert result.engine["model_error_m"] < 1e-6 and len(result.engine["contact_geoms"]) == 2
    assert result.engine["wheel_joints"] == [] and "wheels" not in summary(result)  # no wheels: nothing servoed extra
    assert max(result.start_foot_gap_m.values()) < 1e-3


def test_locked_wheels_do_not_roll(balance_task):
    """A path that pitches every leg (base 5 cm down and pitched 0.2 rad, wheel centres kept where they stand): the plan
    turns each locked wheel with its ankle by 32-39 deg, which on the ground rolls it when the wheel is welded (the old
    model: 26 mm); servoed not to roll, the wheels stay put (4 mm)."""
    from dataclasses import replace

    task, robot = balance_task, balance_task.robot
    path = _shift_base(task, 0.0, 0.637, level=True, pitch_end=0.2)
    assert task.constraint.satisfied(path, np.linspace(0.687, 0.637, len(path))[:, None]).all()
    ankles = [robot.frame_pose(path[[0, -1]], f"ankle2_{i}")[1] for i in range(1, 5)]  # each (2, 3, 3)
    assert min(np.degrees(np.arccos((np.trace(R[0].T @ R[1]) - 1) / 2)) for R in ankles) > 30.0
    rolled = check_path(robot, path, FEET, replace(FAST, servo_wheels=False))
    held = check_path(robot, path, FEET, FAST)
    assert rolled.engine["wheel_joints"] == [] and rolled.engine["welded_joints"] == held.engine["welded_joints"] + 4
    assert held.engine["wheel_joints"] == [f"j_wheel_{i}" for i in range(1, 5)]
    assert rolled.upright and rolled.max_slip_m > 0.02 and not rolled.stable  # the wheels rolled
    assert held.stable and held.max_slip_m < 0.01 and held.max_tilt_deg < 1.0 and held.base_drift_m < 0.01
    assert held.max_tracking_error_rad < 0.03  # the wheel servos held their targets too
    assert "wheels servoed not to roll: j_wheel_1" in summary(held)


def test_the_balance_task_stands_on_its_wheels():
    """The balance task's feet are contact frames on the ankle links; the wheels hang from those links by locked joints.
    The wheel cylinders are contact geometry (they were dropped, and the robot stood 7 cm low on its ankle housings)
    and the wheel joints are servoed; in the reference stance the plan's contacts are on the ground as they are."""
    from manifoldgen.tasks import get_task

    task = get_task("balance", "centauro")
    result = check_path(task.robot, task.home[None], [f"contact_{i}" for i in range(1, 5)],
                        PhysicsSettings(settle_s=0.3, hold_s=0.0))
    assert result.engine["wheel_joints"] == [f"j_wheel_{i}" for i in range(1, 5)]
    assert sum(g.startswith("wheel_") for g in result.engine["contact_geoms"]) == 4
    assert abs(result.engine["start_shift_m"]) < 1e-3 and max(result.start_foot_gap_m.values()) < 1e-3
    assert result.stable and result.max_slip_m < 0.005 and result.max_tilt_deg < 1.0


@pytest.fixture(scope="module")
def talos_task():
    from manifoldgen.tasks import get_task

    return get_task("balance", "talos")


def _talos_shift(task, x_end, count=5):
    """(count, n): talos's home with the base moved to base_x = x_end in steps, each state projected onto the
    balance constraint (soles flat where they stand) at base height 0.98 m."""
    both = ConstraintSet([task.constraint, JointLinearConstraint(task.robot, np.eye(task.robot.n)[[0]], [[0.0]])])
    states = [task.home]
    for x in np.linspace(0.0, x_end, count)[1:]:
        res = project(both, states[-1], [0.98, x])
        assert res.converged[0]
        states.append(res.q[0])
    return np.array(states)


def test_talos_stands_on_its_whole_soles(talos_task):
    """Talos (90 kg) holds its balance task's home: the standing legs' servos are stiff enough for the robot they
    carry (with the ankles' own inertia alone they sagged and tilted the base 9.5 deg), and it stands on its soles'
    outlines (boxes from the ankle meshes' flat bottoms), not on the three deepest vertices of their hulls."""
    result = check_path(talos_task.robot, talos_task.home[None], ["left_sole_link", "right_sole_link"],
                        PhysicsSettings(settle_s=1.0, hold_s=0.0))
    assert result.upright and result.max_tilt_deg < 1.0 and result.max_slip_m < 0.002
    assert result.max_tracking_error_rad < 0.01
    for lo_x, hi_x, lo_y, hi_y in result.engine["flat_soles"].values():  # the sole: 0.2 m x 0.124 m
        assert lo_x < -0.1 and hi_x > 0.09 and lo_y < -0.06 and hi_y > 0.06
    assert {"leg_left_5_joint", "leg_right_5_joint"} <= set(result.engine["stance_servos"])  # ankles
    assert result.effort_joint is not None and result.max_effort_ratio > 0  # URDF effort limits: reported, not applied
    assert not any(j.startswith("arm") for j in result.engine["stance_servos"])


def test_talos_balanced_path_stays_up_and_unbalanced_falls(talos_task):
    """The check can still fail on talos: the base 3 cm forward (CoM 4.5 cm inside the margin) stays upright,
    the base 0.2 m forward with the soles kept (CoM 7.6 cm beyond the constraint's polygon) falls."""
    feet = ["left_sole_link", "right_sole_link"]
    settings = PhysicsSettings(settle_s=0.2, hold_s=1.0, seconds_per_rad=1.0, seconds_per_m=5.0)
    c = talos_task.constraint
    balanced, unbalanced = _talos_shift(talos_task, 0.03), _talos_shift(talos_task, 0.2)
    assert c.satisfied(balanced, np.full((len(balanced), 1), 0.98)).all()
    assert np.abs(c.residual(unbalanced, [0.98])).max() < 1e-5 and c.inequality(unbalanced[-1], [0.98]).max() > 0.09
    up = check_path(talos_task.robot, balanced, feet, settings)
    assert up.upright and up.stable and up.max_tilt_deg < 2.0 and up.max_slip_m < 0.01
    down = check_path(talos_task.robot, unbalanced, feet, settings)
    assert down.fell and not down.upright


def test_each_segment_is_eased_from_rest_within_speed_and_acceleration_limits(talos_task):
    """A short base shift is paced by the base's acceleration limit, a long joint swing by its speed limit; the
    planned motion is at rest at every waypoint and never exceeds either limit (no kick at the waypoints)."""
    from manifoldgen.physics.simulate import Simulation as _Simulation

    settings, home, n = PhysicsSettings(), talos_task.home, talos_task.robot.n
    path = np.stack([home, home + 0.01 * np.eye(n)[0], home + 0.01 * np.eye(n)[0] + 0.5 * np.eye(n)[20]])
    sim = _Simulation(talos_task.robot, ["left_sole_link", "right_sole_link"], settings, home)
    stamps, motion = sim.schedule(path)
    np.testing.assert_allclose(np.diff(stamps), [np.sqrt(10 / np.sqrt(3) * 0.01 / settings.max_acceleration_m),
                                                 1.875 * settings.seconds_per_rad * 0.5])
    dt = 1e-3
    t = settings.settle_s + np.arange(-0.1, motion + 0.1, dt)
    q = np.stack([sim._plan_at(path, stamps, motion, ti) for ti in t])
    v, a = np.diff(q, axis=0) / dt, np.diff(q, n=2, axis=0) / dt ** 2
    assert np.abs(v[:, 0]).max() <= 1 / settings.seconds_per_m and np.abs(a[:, 0]).max() <= 0.1 * 1.01
    assert np.abs(v[:, 20]).max() <= 1 / settings.seconds_per_rad * 1.01 and np.abs(a[:, 20]).max() <= 1.0 * 1.01
    at_waypoints = np.searchsorted(t, settings.settle_s + stamps[1:-1])
    assert np.abs(v[at_waypoints]).max() < 1e-3  # at rest at the inner waypoint
