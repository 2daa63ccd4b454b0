"""The dual-arm tray (paper Section V-B): task files on pr2 and baxter, collected rows, the tray as an object
checked against the robot and the scene, and its bad inputs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from manifoldgen.collision import CollisionChecker
from manifoldgen.data import collect
from manifoldgen.errors import ManifoldgenError
from manifoldgen.scene import Scene, task_checker
from manifoldgen.shapes import Attached
from manifoldgen.space import ConstrainedSpace, densify
from manifoldgen.tasks import get_task, load_task_file, task_from_spec

ROBOTS = ("pr2", "baxter")


@pytest.fixture(scope="module", params=ROBOTS)
def task(request):
    return get_task("dualarm", request.param)


def tray_pose(task, q):
    """World position (3,) and rotation (3, 3) of the tray's centre at ``q (n,)``."""
    held = Attached.from_dict(task.attached)
    p, R = task.robot.frame_pose(q[None], held.frame)
    return p[0] + R[0] @ held.shape.pose.position, R[0]


def test_task_files_hold_the_tray_at_home(task):
    c = task.constraint
    assert c.condition.names == ("distance", "pitch") and len(c.condition.grid) == 24  # 6 d x 4 pitch
    np.testing.assert_allclose(np.unique(np.diff(np.unique(c.condition.grid[:, 1]))), np.pi / 4, atol=1e-6)
    assert np.all(c.tolerance == 0.01) and c.m == 9
    assert c.satisfied(task.home, task.home_condition)[0]
    assert not task_checker(task).in_collision(task.home)[0]
    rebuilt = task_from_spec(json.loads(json.dumps(task.spec())))
    assert rebuilt.attached == task.attached and rebuilt.spec() == task.spec()
    # the grippers are d apart, and the tray is level at pitch 0
    part = c.parts[0]
    pa = task.robot.frame_pose(task.home[None], part.frame_a)[0][0]
    pb = task.robot.frame_pose(task.home[None], part.frame_b)[0][0]
    assert np.linalg.norm(pb - pa) == pytest.approx(task.home_condition[0], abs=0.01)
    thin = int(np.argmin(Attached.from_dict(task.attached).shape.size))
    assert abs(tray_pose(task, task.home)[1][2, thin]) > 0.999  # the thin axis is vertical


def test_collected_rows_satisfy_the_residuals_and_keep_the_tray_clear(task):
    corners = np.array([[0.2, -np.pi / 4], [0.7, np.pi / 2]])
    data = collect(task, 6, seed=1, conditions=corners, batch=128, progress=False)
    assert len(data) == 12
    for y in corners:
        rows = data.q[np.all(data.y == y, axis=1)]
        assert len(rows) == 6 and task.constraint.satisfied(rows, y).all()
        _, R = tray_pose(task, rows[0])
        pitch = task.constraint.parts[1]
        np.testing.assert_allclose(pin.log3(pitch.target(np.array([[y[1]]]))[0].T @ R), 0, atol=0.011)
    assert not task_checker(task).in_collision(data.q).any()
    assert data.meta["task"]["attached"]["name"] == "tray"


def test_only_the_tray_hits_an_obstacle_and_its_holding_links_are_ignored():
    task = get_task("dualarm", "pr2")
    centre, _ = tray_pose(task, task.home)
    block = {"name": "block", "type": "box", "size": [0.05, 0.05, 0.05],
             "pose": {"position": (centre + [0.05, 0.0, 0.03]).tolist()}}
    scene = Scene.from_json(json.dumps({"obstacles": [block], "start": task.home.tolist(),
                                        "goal": task.home.tolist(), "condition": [0.3, 0.0]}))
    scene.attached = Attached.from_dict(task.attached)
    checker = scene.checker(task.robot)
    assert checker.in_collision(task.home)[0]
    assert checker.collisions(task.home) == [("tray", "block")]
    robot_only = CollisionChecker(task.robot, obstacles=[o.geometry_object() for o in scene.obstacles])
    assert not robot_only.in_collision(task.home)[0]
    # the fingers pinch the tray: without touch links the same configuration collides with them
    held = Attached.from_dict(task.attached)
    strict = CollisionChecker(task.robot, attached=[held.geometry_object(task.robot)], touch=[[]])
    assert any("finger" in a + b for a, b in strict.collisions(task.home))
    assert not task_checker(task).in_collision(task.home)[0]


def _variant(tmp_path, robot: str, old: str, new: str):
    file = get_task("dualarm", robot).file
    text = file.read_text().replace('"scenes/', f'"{file.parent}/scenes/')
    assert old in text
    path = tmp_path / f"dualarm-{robot}.toml"
    path.write_text(text.replace(old, new))
    return path


def test_a_tray_through_the_robot_at_home_is_one_clear_line(tmp_path):
    path = _variant(tmp_path, "pr2", "pose = { position = [0.13, 0.15, 0.0] }",
                    "pose = { position = [-0.4, 0.15, 0.0] }")  # back through the wrists
    with pytest.raises(ManifoldgenError, match=r"line \d+: the held box 'tray' collides with the robot at home") \
            as info:
        load_task_file(path)
    assert "\n" not in str(info.value)


def test_closed_chain_frames_on_one_arm_are_refused(tmp_path):
    path = _variant(tmp_path, "pr2", 'frame_b = "l_gripper_tool_frame"', 'frame_b = "r_wrist_flex_link"')
    with pytest.raises(ManifoldgenError, match="on one kinematic chain"):
        load_task_file(path)


def _scene_variant(tmp_path, **changes):
    data = json.loads((get_task("dualarm", "pr2").scenes["tray-over"]).read_text())
    data.update(changes)
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(data))
    return str(path)


@pytest.mark.slow
@pytest.mark.parametrize("changes, message", [
    ({"condition": [3.0, 0.0]}, r"no configuration of pr2 satisfies the task at condition distance = 3, pitch = 0 "),
    ({"start": {"position": [2.0, -0.5, 0.5]}}, r"puts r_gripper_tool_frame at the start target .*within reach"),
])
def test_unreachable_conditions_and_targets_are_one_clear_line(tmp_path, changes, message):
    from manifoldgen.scene import get_scene

    with pytest.raises(ManifoldgenError, match=message) as info:
        get_scene(get_task("dualarm", "pr2"), _scene_variant(tmp_path, **changes))
    assert "\n" not in str(info.value)


# a pr2 configuration on the tray manifold at (0.3 m, 0) whose arms cross: the right upper arm, elbow and forearm
# go through the tray (and the left gripper through the right upper arm)
TRAY_THROUGH_ARM = [0.0, 0.4818, -0.3854, 0.8, -2.3212, 2.443, -2.079, 1.8204, 0.3373, -0.5236, 0.9845, -2.2464,
                    2.414, -2.094, 1.6416]


def _cli_error(args) -> str:
    """The one error line of ``manifoldgen ARGS``, which must exit 2."""
    from typer.testing import CliRunner

    from manifoldgen.cli import app

    result = CliRunner().invoke(app, [str(a) for a in args], terminal_width=400)
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1, result.output
    return errors[0]


@pytest.mark.slow
def test_the_issues_bad_inputs_exit_2_with_one_line(tmp_path):
    """The dual-arm issue's bad inputs through the CLI: two frames that are the same, a (d, pitch) no
    configuration reaches, a tray target out of both arms' reach, a start where the tray goes through an arm."""
    same = _variant(tmp_path, "pr2", 'frame_b = "l_gripper_tool_frame"', 'frame_b = "r_gripper_tool_frame"')
    assert "closed chain frames are both 'r_gripper_tool_frame'; give two different frames" in _cli_error(
        ["collect", same, "--per-condition", "2", "-o", tmp_path / "x.npz"])
    plan = ["plan", "dualarm", "--robot", "pr2", "--sampler", "project", "--time", "1", "-o", tmp_path / "p.npz",
            "--scene"]
    assert "no configuration of pr2 satisfies the task at condition distance = 3, pitch = 0" in _cli_error(
        [*plan, _scene_variant(tmp_path, condition=[3.0, 0.0])])
    assert "at the goal target [0.55, 1.5, 0.5]" in _cli_error(
        [*plan, _scene_variant(tmp_path, goal={"position": [0.55, 1.5, 0.5]})])
    task = get_task("dualarm", "pr2")
    assert task.constraint.satisfied(np.array(TRAY_THROUGH_ARM), [0.3, 0.0])[0]
    assert {"r_forearm_link_0", "tray"} in [set(pair) for pair in task_checker(task).collisions(TRAY_THROUGH_ARM)]
    assert _cli_error([*plan, _scene_variant(tmp_path, start=TRAY_THROUGH_ARM)]).startswith(
        "error: start configuration is in collision: ")
    assert not list(tmp_path.glob("*.npz"))


EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _outside_check(tmp_path, *files) -> subprocess.CompletedProcess:
    """examples/check_path.py on ``files`` with manifoldgen made unimportable."""
    fake = tmp_path / "no_manifoldgen" / "manifoldgen"
    fake.mkdir(parents=True, exist_ok=True)
    (fake / "__init__.py").write_text("raise ImportError('an outside checker must not import manifoldgen')\n")
    return subprocess.run([sys.executable, str(EXAMPLES / "check_path.py"), *map(str, files)], capture_output=True,
                          text=True, env={**os.environ, "PYTHONPATH": str(tmp_path / "no_manifoldgen")}, timeout=120)


@pytest.mark.slow
def test_a_planned_tray_path_is_valid_state_by_state_and_outside(tmp_path):
    """The tray carried along the table (the tray-over scene without its block, so that it plans in a second):
    the path holds the chain and the tray's rotation at every state, inside and outside manifoldgen; the same
    path with a post in the tray's way is refused for the tray's collision alone."""
    from manifoldgen.query import run_query, save_path
    from manifoldgen.scene import get_scene

    task = get_task("dualarm", "pr2")
    data = json.loads(task.scenes["tray-over"].read_text())
    data["obstacles"] = [o for o in data["obstacles"] if o["name"] == "table"]
    (tmp_path / "along.json").write_text(json.dumps(data))
    scene = get_scene(task, str(tmp_path / "along.json"))
    result, meta = run_query(task, scene, "project", "rrtconnect", seed=0, time_limit=20.0)
    assert result.solved and meta["validation"]["valid"]
    space_report = ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot)).validate_path(
        result.path)
    assert space_report.valid and space_report.worst_violation <= 1.0 and space_report.states_checked > 10
    assert [o.get("name") for o in meta["scene"]] == ["table", "tray"] and meta["task"]["attached"]["name"] == "tray"
    save_path(tmp_path / "ok.npz", result, meta)
    # a post standing where the tray passes at the path's middle, clear of the robot's links
    states = densify(result.path, 0.01)[0]
    centre, _ = tray_pose(task, states[len(states) // 2])
    post = {"name": "post", "type": "box", "size": [0.04, 0.04, 0.04],
            "pose": {"position": (centre + [0.1, 0.0, 0.0]).tolist(), "quaternion": [0, 0, 0, 1]}}
    robot_only = CollisionChecker(task.robot, obstacles=[Scene.from_json(json.dumps(
        {"obstacles": [post], "start": [0.0], "goal": [0.0], "condition": [0.0]})).obstacles[0].geometry_object()])
    assert not robot_only.in_collision(states).any()
    hit = {**meta, "scene": [*meta["scene"][:-1], post, meta["scene"][-1]]}
    save_path(tmp_path / "hit.npz", result, hit)
    out = _outside_check(tmp_path, tmp_path / "ok.npz", tmp_path / "hit.npz")
    lines = out.stdout.strip().splitlines()
    assert out.returncode == 1, out.stdout + out.stderr
    assert "1 obstacle(s), 1 held object(s)" in out.stdout and "2 obstacle(s), 1 held object(s)" in out.stdout
    assert next(x for x in lines if x.startswith(str(tmp_path / "ok.npz"))).endswith(": VALID")
    assert "collision: tray with post" in out.stdout
    assert next(x for x in lines if x.startswith(str(tmp_path / "hit.npz"))).endswith(": INVALID")


def test_the_dualarm_demo_is_registered_and_level_tray_rows_hold_the_tray_level():
    """The demo is registered (it runs the default pipeline; the whole demo is timed on the benchmarks page) and
    the task's rows at pitch 0 hold the tray level."""
    from manifoldgen.demos import DEMOS

    assert DEMOS["dualarm"] == "manifoldgen.demos.dualarm"
    task = get_task("dualarm", "pr2")
    conditions = task.condition.grid[np.isclose(task.condition.grid[:, 1], 0.0)]
    np.testing.assert_allclose(conditions, [[d, 0.0] for d in (0.2, 0.3, 0.4, 0.5, 0.6, 0.7)])
    data = collect(task, 4, seed=3, conditions=conditions, batch=64, progress=False)
    assert len(data) == 24 and task.constraint.satisfied(data.q, data.y).all()
    _, R = task.robot.frame_pose(data.q, "r_gripper_tool_frame")
    assert np.all(R[:, 2, 2] > 0.9999)  # pitch 0: the tray is level


def test_collect_near_home_keeps_rows_on_the_homes_branch():
    """baxter's tray manifold has many IK branches (roll joints over +-3 rad); uniform seeds spread the rows over
    all of them, and a unimodal CVAE averages them into a pose far from every query solved near the home.
    ``near_home`` seeds the projection around the home: valid rows, much closer to it, recorded in the meta."""
    task = get_task("dualarm", "baxter")
    y = np.array([[0.3, 0.0]])
    near = collect(task, 16, seed=2, conditions=y, batch=128, progress=False, near_home=0.5)
    uniform = collect(task, 16, seed=2, conditions=y, batch=128, progress=False)
    assert task.constraint.satisfied(near.q, near.y).all() and not task_checker(task).in_collision(near.q).any()
    gap = [np.median(np.linalg.norm(d.q - task.home, axis=1)) for d in (near, uniform)]
    assert gap[0] < 0.5 * gap[1]
    assert near.meta["near_home"] == 0.5 and "near_home" not in uniform.meta
    with pytest.raises(ManifoldgenError, match="near_home must be"):
        collect(task, 4, seed=0, conditions=y, near_home=-1.0, progress=False)
