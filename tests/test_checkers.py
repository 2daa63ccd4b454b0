"""The outside checkers (examples/check_dataset.py, examples/check_path.py): for every built-in constraint
type they accept what manifoldgen made, reject corrupted rows with the right reason, refuse to vouch for a
user type (exit 3), and never import manifoldgen."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from manifoldgen.data import collect
from manifoldgen.dataset import Dataset
from manifoldgen.tasks import get_task, task_from_meta
from refusals import set_key

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
PANDA = ", ".join(f'"panda_joint{i}"' for i in range(1, 8))
PANDA_HOME = "[0.0, -0.785398, 0.0, -2.35619, 0.0, 1.5707, 0.785398]"
DOWN = "[[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]"  # tool z axis straight down
PR2_ARMS = ", ".join(['"torso_lift_joint"'] + [f'"{s}_{j}"' for s in "rl" for j in (
    "shoulder_pan_joint", "shoulder_lift_joint", "upper_arm_roll_joint", "elbow_flex_joint", "forearm_roll_joint",
    "wrist_flex_joint", "wrist_roll_joint")])
LEGS = ", ".join(f'"{j}_{i}"' for i in range(1, 5) for j in ("hip_pitch", "knee_pitch", "ankle_pitch"))
CENTAURO_HOME = ("[0.0, 0.0, 0.687, 0.0, 0.0, 0.0, -1.25409, -1.55576, -0.301666, 1.25409, 1.55576, 0.301666, "
                 "1.25409, 1.55576, 0.301667, -1.25409, -1.55576, -0.301667]")

USER_MODULE = Path(__file__).resolve().parent.parent / "examples" / "user_task" / "tool_down.py"  # the docs' example

# type -> (task file body after name, rows per condition)
TASKS = {
    "pose": f'''robot = "panda"
group = [{PANDA}]
[[constraints]]
type = "pose"
frame = "panda_hand_tcp"
rotation = {DOWN}
position_axes = ["x", "z"]
orientation_axes = ["x", "y"]
values = [[0.4, 0.3], [0.5, 0.4]]
''',
    "orientation": f'''robot = "panda"
group = [{PANDA}]
[[constraints]]
type = "orientation"
frame = "panda_hand_tcp"
axis = [0.0, 0.0, 1.0]
direction = [0.0, 0.0, -1.0]
''',
    "plane": f'''robot = "panda"
group = [{PANDA}]
[[constraints]]
type = "plane"
frame = "panda_hand_tcp"
normals = [[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]]
values = [[0.4, 0.3]]
''',
    "joint_linear": f'''robot = "panda"
group = [{PANDA}]
[[constraints]]
type = "joint_linear"
coefficients = [[1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0]]
values = [[0.0], [0.5]]
''',
    "set": f'''robot = "panda"
group = [{PANDA}]
[[constraints]]
type = "orientation"
frame = "panda_hand_tcp"
direction = [0.0, 0.0, -1.0]
[[constraints]]
type = "plane"
frame = "panda_hand_tcp"
normals = [[0.0, 0.0, 1.0]]
values = [[0.3], [0.5]]
''',
    "closed_chain": f'''robot = "pr2"
group = [{PR2_ARMS}]
[[constraints]]
type = "closed_chain"
frame_a = "r_gripper_tool_frame"
frame_b = "l_gripper_tool_frame"
rotation = [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]
values = [[0.3], [0.4]]
''',
    "balance": f'''robot = "centauro"
floating_base = true
base_bounds = [[-0.2, -0.2, 0.5], [0.2, 0.2, 1.0]]
group = ["base_x", "base_y", "base_z", "base_yaw", "base_pitch", "base_roll", {LEGS}]
home = {CENTAURO_HOME}
home_condition = [0.687]
[[constraints]]
type = "balance"
feet = ["wheel_1", "wheel_2", "wheel_3", "wheel_4"]
foot_positions = [[0.3494, 0.3498, 0.0], [0.3494, -0.3498, 0.0], [-0.3494, 0.3498, 0.0], [-0.3494, -0.3498, 0.0]]
base_frame = "pelvis"
values = [[0.66], [0.69]]
''',
    "user": f'''robot = "panda"
group = [{PANDA}]
home = {PANDA_HOME}
home_condition = [0.4]
[[constraints]]
type = "usercon:ToolDownAtX"
frame = "panda_hand_tcp"
values = [[0.4], [0.5]]
''',
    "user_in_set": f'''robot = "panda"
group = [{PANDA}]
home = {PANDA_HOME}
home_condition = [0.45, 0.4]
[[constraints]]
type = "usercon:ToolDownAtX"
frame = "panda_hand_tcp"
values = [[0.45]]
[[constraints]]
type = "plane"
frame = "panda_hand_tcp"
normals = [[0.0, 0.0, 1.0]]
values = [[0.4]]
''',
}
ROWS = {"closed_chain": 6, "balance": 6}
BUILTIN = ["pose", "orientation", "plane", "joint_linear", "set", "closed_chain", "balance"]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """Task files, the user's constraint module, and a fake ``manifoldgen`` package that fails on import
    (put first on the checkers' PYTHONPATH: they must not import manifoldgen)."""
    base = tmp_path_factory.mktemp("checkers")
    (base / "usercon.py").write_text(USER_MODULE.read_text())
    for kind, body in TASKS.items():
        (base / f"{kind}.toml").write_text(f'name = "check-{kind}"\n{body}')
    fake = base / "no_manifoldgen" / "manifoldgen"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError('an outside checker must not import manifoldgen')\n")
    return base


@pytest.fixture(scope="module")
def datasets(folder):
    """kind -> (dataset file, Dataset): a few rows per condition, collected by manifoldgen."""
    out = {}
    for kind in TASKS:
        task = get_task(str(folder / f"{kind}.toml"))
        path = folder / f"{kind}.npz"
        out[kind] = path, collect(task, ROWS.get(kind, 8), seed=0, out=path, batch=256, progress=False)
    return out


def run(folder, script: str, *args) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(folder / "no_manifoldgen")}
    return subprocess.run([sys.executable, str(EXAMPLES / script), *map(str, args)], capture_output=True, text=True,
                          env=env, timeout=120)


def corrupt(dataset: Dataset, path: Path, rows, joint: int, shift: float, meta: dict | None = None) -> Path:
    q = dataset.q.copy()
    q[rows, joint] += shift
    Dataset(q, dataset.y, meta or dataset.meta).save(path)
    return path


def test_checkers_import_only_numpy_pinocchio_coal():
    import ast

    allowed = {"numpy", "pinocchio", "coal", "recheck", "check_path", "__future__", *sys.stdlib_module_names}
    for name in ("check_dataset.py", "check_path.py", "check_roadmap.py", "recheck.py"):
        tree = ast.parse((EXAMPLES / name).read_text())
        modules = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        modules |= {n.module.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        assert modules <= allowed, (name, modules - allowed)


@pytest.mark.slow
def test_every_builtin_type_is_accepted(folder, datasets):
    """One checker run over every built-in type's dataset (and the fake manifoldgen package in the way)."""
    files = [datasets[kind][0] for kind in BUILTIN]
    result = run(folder, "check_dataset.py", *files)
    assert result.returncode == 0, result.stdout + result.stderr
    verdicts = [line for line in result.stdout.splitlines() if not line.startswith("  ")]
    assert len(verdicts) == len(BUILTIN)
    for kind, line in zip(BUILTIN, verdicts):
        assert line.endswith(": VALID") and "all three 100.00%" in line, line
        assert (f"on {'pr2' if kind == 'closed_chain' else 'centauro' if kind == 'balance' else 'panda'};" in line)
    assert "set of orientation + plane" in verdicts[BUILTIN.index("set")]
    assert result.stdout.count("sha256") == len(BUILTIN) and "matches" in result.stdout


@pytest.mark.slow
@pytest.mark.parametrize("kind,joint,shift", [("pose", 3, 0.05), ("orientation", 5, 0.05), ("plane", 0, 0.05),
                                              ("joint_linear", 1, 0.05), ("set", 1, 0.05), ("closed_chain", 2, 0.05),
                                              ("balance", 0, 0.05)])
def test_shifted_joint_is_rejected_with_the_constraint_reason(folder, datasets, kind, joint, shift):
    path, dataset = datasets[kind]
    bad = corrupt(dataset, folder / f"{kind}-bad.npz", [1, 4], joint, shift)
    result = run(folder, "check_dataset.py", bad)
    assert result.returncode == 1, result.stdout + result.stderr
    verdict = result.stdout.splitlines()[-1]
    assert verdict.endswith(f"INVALID (2 of {len(dataset)} rows)"), verdict
    assert "row 1 (y = " in result.stdout and "row 4 (y = " in result.stdout
    assert f"constraint: {kind if kind != 'set' else ''}" in result.stdout and "x its tolerance" in result.stdout


def test_limits_collisions_and_inequalities_are_rechecked(folder, datasets):
    from manifoldgen.collision import CollisionChecker

    path, dataset = datasets["pose"]
    task = task_from_meta(dataset.meta)
    corrupt(dataset, folder / "over.npz", [0], 3, task.robot.upper[3] - dataset.q[0, 3] + 0.01)
    q = task.robot.sample_uniform(400, np.random.default_rng(0))
    clash = q[CollisionChecker(task.robot).in_collision(q)][0]
    rows = dataset.q.copy()
    rows[2] = clash
    Dataset(rows, dataset.y, dataset.meta).save(folder / "clash.npz")
    bpath, balance = datasets["balance"]
    meta = json.loads(json.dumps(balance.meta))
    for where in (meta, meta["task"]):
        where["constraint"]["margin"] = 0.6  # wider than the support polygon: the CoM can never be inside
    Dataset(balance.q, balance.y, meta).save(folder / "margin.npz")
    result = run(folder, "check_dataset.py", folder / "over.npz", folder / "clash.npz", folder / "margin.npz")
    assert result.returncode == 1
    out = result.stdout
    assert "row 0 (y = " in out and "limits: panda_joint4 = " in out and "not in [" in out
    assert "row 2 (y = " in out and "collision: " in out and " with " in out
    assert "inequality: balance CoM beyond support edge" in out and "0.6 m margin" in out
    assert f"INVALID ({len(balance)} of {len(balance)} rows)" in out


def test_user_type_cannot_be_rechecked(folder, datasets):
    result = run(folder, "check_dataset.py", datasets["user"][0])
    assert result.returncode == 3, result.stdout + result.stderr
    assert "CANNOT RECHECK the user constraint type 'usercon:ToolDownAtX'" in result.stdout
    assert "joint limits and collisions are still checked" in result.stdout
    assert "constraint NOT rechecked (user type usercon:ToolDownAtX)" in result.stdout
    assert result.stdout.splitlines()[-1].endswith("CANNOT RECHECK the constraint (user type)")
    # a set with a user part: its built-in parts are still rechecked, condition and tolerance split around it
    path, dataset = datasets["user_in_set"]
    result = run(folder, "check_dataset.py", path)
    assert result.returncode == 3 and "built-in parts within tolerance 100.00%" in result.stdout
    bad = corrupt(dataset, folder / "user-bad.npz", [0], 1, 0.1)
    result = run(folder, "check_dataset.py", bad)
    assert result.returncode == 1 and "constraint: plane panda_hand_tcp offset" in result.stdout
    # limits are checked for a user type too
    bad = corrupt(datasets["user"][1], folder / "user-limit.npz", [0], 0, 5.0)
    result = run(folder, "check_dataset.py", bad)
    assert result.returncode == 1 and "limits: panda_joint1" in result.stdout


def test_robot_identity_is_verified_and_found_by_content(folder, datasets):
    path, dataset = datasets["plane"]
    meta = json.loads(json.dumps(dataset.meta))
    meta["task"]["robot"]["urdf_sha256"] = "0" * 64
    Dataset(dataset.q, dataset.y, meta).save(folder / "other-urdf.npz")
    meta = json.loads(json.dumps(dataset.meta))
    meta["task"]["robot"]["name"] = meta["task"]["robot_source"] = meta["robot"] = "renamed"
    meta["task"]["srdf_source"] = None
    Dataset(dataset.q, dataset.y, meta).save(folder / "renamed.npz")
    result = run(folder, "check_dataset.py", folder / "other-urdf.npz")
    assert result.returncode == 3 and "WARNING: URDF sha256 differs" in result.stdout
    assert "UNVERIFIED" in result.stdout.splitlines()[-1]
    result = run(folder, "check_dataset.py", folder / "renamed.npz")
    assert result.returncode == 0 and "panda.urdf (URDF sha256" in result.stdout, result.stdout
    result = run(folder, "check_dataset.py", folder / "renamed.npz", "--urdf", folder / "nowhere.urdf")
    assert result.returncode == 3 and "no such file" in result.stdout


def test_recomputed_residuals_equal_manifoldgen_residuals(datasets):
    """The checker's pinocchio residuals and inequalities match the package's, off the manifold too."""
    sys.path.insert(0, str(EXAMPLES))
    from recheck import Checker, State

    for kind in BUILTIN:
        path, dataset = datasets[kind]
        task = task_from_meta(dataset.meta)
        q = np.clip(dataset.q + 0.05 * np.random.default_rng(1).normal(size=dataset.q.shape), task.robot.lower,
                    task.robot.upper)
        checker = Checker(json.loads(json.dumps(dataset.meta)), dataset.y.shape[1])
        F, G = task.constraint.residual(q, dataset.y), task.constraint.inequality(q, dataset.y)
        mine = [np.concatenate([p.residual(s, y[sl]) for p, sl in zip(checker.constraint.parts,
                                                                    checker.constraint.y_slices)])
                for s, y in ((State(checker.robot, row), y) for row, y in zip(q, dataset.y))]
        np.testing.assert_allclose(np.array(mine), F, atol=1e-9, err_msg=kind)
        ineq = [np.concatenate([p.inequality(State(checker.robot, row), y[sl]) for p, sl in
                                zip(checker.constraint.parts, checker.constraint.y_slices)])
                for row, y in zip(q, dataset.y)]
        np.testing.assert_allclose(np.array(ineq).reshape(G.shape), G, atol=1e-9, err_msg=kind)
        lower, upper = checker.robot.lower, checker.robot.upper
        np.testing.assert_allclose(lower, task.robot.lower)
        np.testing.assert_allclose(upper, task.robot.upper)


def _path_file(folder, datasets, name: str, scene: dict, rotate: float = 0.8) -> Path:
    """A path of the orientation task (tool pointing down): joint 7 turns the tool about its own axis,
    so every state of the straight segment stays on the manifold; meta as `manifoldgen plan` writes it."""
    from manifoldgen.scene import Scene

    path, dataset = datasets["orientation"]
    task = task_from_meta(dataset.meta)
    start = dataset.q[0]
    goal = start.copy()
    goal[6] = np.clip(goal[6] + rotate, task.robot.lower[6], task.robot.upper[6] - 0.01)
    scene_obj = Scene.from_json(json.dumps({"name": name, "start": start.tolist(), "goal": goal.tolist(),
                                            "condition": [0.0], **scene}))
    mid = start + 0.5 * (goal - start)
    meta = {**task.meta(), "format_version": 2, "kind": "path", "condition": [], "condition_names": [],
            "scene_name": name, "scene": scene_obj.to_meta(task.robot), "start": start.tolist(),
            "goal": goal.tolist(), "validation": {"resolution": 0.01}}
    out = folder / f"{name}.npz"
    np.savez(out, meta=np.array(json.dumps(meta)), path=np.stack([start, mid, goal]))
    return out


@pytest.mark.slow
def test_paths_with_obstacles_and_a_held_tool(folder, datasets):
    path, dataset = datasets["orientation"]
    task = task_from_meta(dataset.meta)
    hand = task.robot.frame_pose(dataset.q[0], "panda_hand_tcp")[0][0]
    far = {"name": "crate", "type": "box", "size": [0.2, 0.2, 0.2], "pose": {"position": [2.0, 2.0, 0.1]}}
    tool = {"name": "cup", "type": "cylinder", "radius": 0.03, "length": 0.12, "attached_to": "panda_hand_tcp",
            "pose": {"position": [0.0, 0.0, 0.08]}}
    ok = _path_file(folder, datasets, "ok", {"obstacles": [far], "attached": tool})
    below = {**far, "name": "table", "pose": {"position": (hand - [0.0, 0.0, 0.2]).tolist()}}  # under the cup
    hit = _path_file(folder, datasets, "tool-hits", {"obstacles": [below], "attached": tool})
    long = {**tool, "length": 0.6, "pose": {"position": [0.0, 0.0, -0.25]}}  # through the arm
    through = _path_file(folder, datasets, "tool-through-arm", {"obstacles": [far], "attached": long})
    meta = json.loads(str(np.load(ok)["meta"]))
    meta["constraint"]["direction"] = meta["task"]["constraint"]["direction"] = [0.0, 1.0, -1.0]  # another manifold
    np.savez(folder / "off.npz", meta=np.array(json.dumps(meta)), path=np.load(ok)["path"])
    # the package's own rule agrees on the valid file, state by state
    sys.path.insert(0, str(EXAMPLES))
    from check_path import densify
    from manifoldgen.scene import Scene

    scene = Scene.from_json(json.dumps({"start": [0.0] * 7, "goal": [0.0] * 7, "condition": [0.0],
                                        "obstacles": [far], "attached": tool}))
    states = densify(np.load(ok)["path"], 0.01)[0]
    assert task.constraint.satisfied(states, np.zeros((len(states), 0))).all()
    assert not scene.checker(task.robot).in_collision(states).any()

    result = run(folder, "check_path.py", ok)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "1 obstacle(s), 1 held object(s)" in result.stdout
    assert "states checked every 0.01;" in result.stdout and result.stdout.rstrip().endswith(": VALID")
    off = folder / "off.npz"
    for bad, reason in ((hit, "collision: "), (through, "collision: "), (off, "constraint: orientation")):
        result = run(folder, "check_path.py", bad)
        assert result.returncode == 1, result.stdout + result.stderr
        assert "first problem: segment 0 (state 0): " in result.stdout and reason in result.stdout, result.stdout
    result = run(folder, "check_path.py", hit)
    assert "cup with table" in result.stdout or "table with cup" in result.stdout
    result = run(folder, "check_path.py", through)
    assert "cup" in result.stdout and "panda_link" in result.stdout


def test_path_checker_api_and_densification(folder, datasets):
    sys.path.insert(0, str(EXAMPLES))
    from check_path import outside_check

    ok = _path_file(folder, datasets, "api", {"obstacles": []}, rotate=0.3)
    report = outside_check(ok)
    assert report["valid"] and report["status"] == 0 and report["collisions"] == report["outside"] == 0
    assert report["worst"] < 1e-3
    data = np.load(ok)
    steps = np.ceil(np.linalg.norm(np.diff(data["path"], axis=0), axis=1) / 0.01)
    assert report["states"] == steps.sum() + 1 and report["states"] > 20
    assert outside_check(ok, resolution=0.001)["states"] > 9 * report["states"]
    meta = json.loads(str(data["meta"]))
    np.savez(folder / "moved.npz", meta=np.array(json.dumps(meta)), path=data["path"][::-1])
    report = outside_check(folder / "moved.npz")
    assert report["status"] == 1 and "does not start at the recorded start" in report["reason"]
    # a user type: the line says the constraint was not rechecked, and counts no violations it did not measure
    user = {**meta, "constraint": {"type": "usercon:ToolDownAtX"}}
    np.savez(folder / "user-path.npz", meta=np.array(json.dumps(user)), path=data["path"])
    report = outside_check(folder / "user-path.npz")
    assert report["status"] == 3 and report["collisions"] == report["outside"] == 0
    assert "constraint NOT rechecked (user type usercon:ToolDownAtX)" in report["line"]
    assert "violating" not in report["line"] and report["line"].endswith("CANNOT RECHECK the constraint (user type)")


def test_robot_given_as_a_urdf_path_is_found_next_to_the_file(folder, tmp_path):
    """A task on a URDF path (no SRDF): the checker reads the recorded path; moved machines, it finds the
    URDF next to the checked file, by content."""
    import shutil

    from manifoldgen.robot import resolve_robot

    urdf = tmp_path / "robots" / "mypanda.urdf"
    urdf.parent.mkdir()
    urdf.write_text(resolve_robot("panda")[0].read_text() + "\n<!-- a user's copy -->\n")
    task_file = tmp_path / "mine.toml"
    task_file.write_text(TASKS["plane"].replace('robot = "panda"', 'robot = "robots/mypanda.urdf"')
                         .replace("[[constraints]]", 'name = "mine"\n[[constraints]]', 1))
    task = get_task(str(task_file))
    assert task.robot.name == "mypanda" and task.robot.srdf is None
    path = tmp_path / "mine.npz"
    collect(task, 6, seed=0, out=path, batch=256, progress=False)
    result = run(folder, "check_dataset.py", path)
    assert result.returncode == 0, result.stdout + result.stderr
    assert f"{urdf} (URDF sha256" in result.stdout and "matches" in result.stdout
    moved = tmp_path / "elsewhere"
    moved.mkdir()
    shutil.move(path, moved / "mine.npz")
    shutil.move(urdf, moved / "mypanda.urdf")
    result = run(folder, "check_dataset.py", moved / "mine.npz")
    assert result.returncode == 0 and f"{moved / 'mypanda.urdf'} (URDF sha256" in result.stdout, result.stdout
    (moved / "mypanda.urdf").unlink()
    result = run(folder, "check_dataset.py", moved / "mine.npz")
    assert result.returncode == 3 and "pass --urdf PATH" in result.stdout, result.stdout


@pytest.fixture(scope="module")
def wall(tmp_path_factory):
    """(path file, roadmap file) of the panda pose task's wall scene, planned once by `manifoldgen plan --roadmap`
    with the shipped CVAE (seed 0)."""
    from typer.testing import CliRunner

    from manifoldgen.cli import app
    from manifoldgen.models import pretrained_model_dir

    base = tmp_path_factory.mktemp("wall")
    result = CliRunner().invoke(app, ["plan", "pose", "--robot", "panda", "--scene", "wall", "--sampler",
                                      f"cvae:{pretrained_model_dir()}", "--seed", "0", "--time", "60", "--no-picture",
                                      "--roadmap", str(base / "r.npz"), "-o", str(base / "p.npz")])
    assert result.exit_code == 0, result.output
    return base / "p.npz", base / "r.npz"


def _edited(source: Path, out: Path, edit_meta=None, **arrays) -> Path:
    """A copy of a path or roadmap file with ``edit_meta(meta)`` applied and ``arrays`` replaced; a roadmap's
    ``scene_sha256`` recomputed (a tester's edit that keeps the fingerprint matching)."""
    import hashlib

    with np.load(source) as f:
        found = {k: f[k] for k in f.files}
    meta = json.loads(str(found.pop("meta")))
    if edit_meta is not None:
        edit_meta(meta)
    if "scene_sha256" in meta:
        objects = json.dumps(meta["scene"], sort_keys=True, separators=(",", ":"))
        meta["scene_sha256"] = hashlib.sha256(objects.encode()).hexdigest()
    np.savez(out, **{**found, **arrays}, meta=np.array(json.dumps(meta)))
    return out


def test_absurd_resolutions_and_too_many_states_are_refused(wall, tmp_path, monkeypatch, capsys):
    """A resolution outside [1e-5, 0.05] rad (the file's, a roadmap's, a bench folder's or --resolution) cannot
    recheck, nor can a check that would make more than MAX_STATES states; the package's own files pass."""
    sys.path.insert(0, str(EXAMPLES))
    import check_path
    from check_path import main, outside_check
    from check_roadmap import roadmap_check

    path, roadmap = wall
    assert outside_check(path)["status"] == 0 and roadmap_check(roadmap)["status"] == 0
    for value in (1e-300, 100.0, 0.0, float("nan")):
        report = outside_check(_edited(path, tmp_path / "p.npz", set_key("validation", "resolution", value=value)))
        assert report["status"] == 3 and f"meta validation.resolution {value!r} is outside the rechecked range " \
            "[1e-05, 0.05] rad" in report["line"], report["line"]
        report = roadmap_check(_edited(roadmap, tmp_path / "r.npz", set_key("resolution", value=value)))
        assert report["status"] == 3 and f"meta resolution {value!r} is outside" in report["line"], report["line"]
    assert main([str(path), "--resolution", "100"]) == 3
    assert capsys.readouterr().out.strip() == f"{path}: CANNOT RECHECK: --resolution 100.0 is outside the rechecked " \
        "range [1e-05, 0.05] rad; pass --resolution R within it"
    assert "--resolution 1e-06 is outside" in roadmap_check(roadmap, resolution=1e-6)["line"]
    monkeypatch.setattr(check_path, "MAX_STATES", 500)
    for report in (outside_check(path), roadmap_check(roadmap)):
        assert report["status"] == 3 and "states, more than the 500 allowed; pass a coarser --resolution" \
            in report["line"], report["line"]
    # a bench folder: problem.json's resolution, refused once
    bench = tmp_path / "bench"
    bench.mkdir()
    with np.load(path) as f:
        meta, waypoints = json.loads(str(f["meta"])), f["path"]
    (bench / "runs.jsonl").write_text(json.dumps({"method": "m", "run": 0, "solved": True,
                                                  "path": waypoints.tolist()}) + "\n")
    (bench / "problem.json").write_text(json.dumps({**meta, "validation": {"resolution": 0.005}}))
    monkeypatch.undo()
    assert main([str(bench)]) == 0 and "1 solved runs rechecked above" in capsys.readouterr().out
    (bench / "problem.json").write_text(json.dumps({**meta, "validation": {"resolution": 100.0}}))
    assert main([str(bench)]) == 3
    assert capsys.readouterr().out.strip() == f"{bench}: CANNOT RECHECK: problem.json validation.resolution 100.0 is " \
        "outside the rechecked range [1e-05, 0.05] rad; pass --resolution R within it"


@pytest.mark.parametrize("change,named", [
    ({"size": [-0.2, -0.2, -0.2]}, "size [-0.2, -0.2, -0.2] is not 3 positive finite numbers"),
    ({"size": [0.4, float("nan"), 0.6]}, "size [0.4, nan, 0.6] is not 3 positive finite numbers"),
    ({"type": "sphere", "radius": -0.2}, "radius -0.2 is not a positive finite number"),
    ({"type": "sphere", "radius": 0.0}, "radius 0.0 is not a positive finite number"),
    ({"pose": {"position": [float("inf"), 0.0, 0.0]}}, "position [inf, 0.0, 0.0] is not 3 finite numbers"),
])
def test_malformed_scene_objects_are_refused(wall, tmp_path, change, named):
    sys.path.insert(0, str(EXAMPLES))
    from check_path import outside_check
    from check_roadmap import roadmap_check

    def edit(meta):
        meta["scene"][0].update(change)

    path, roadmap = wall
    for report in (outside_check(_edited(path, tmp_path / "p.npz", edit)),
                   roadmap_check(_edited(roadmap, tmp_path / "r.npz", edit))):
        assert report["status"] == 3 and f"CANNOT RECHECK: scene object 'wall_left' {named}" in report["line"] \
            and "(manifoldgen refuses such a scene)" in report["line"], report["line"]


def test_a_locked_joint_outside_its_limits_is_invalid(wall, tmp_path):
    sys.path.insert(0, str(EXAMPLES))
    from check_path import outside_check
    from check_roadmap import roadmap_check

    path, roadmap = wall
    locked = set_key("locked", "panda_finger_joint1", value=5.0)
    report = outside_check(_edited(path, tmp_path / "p.npz", locked))
    assert report["status"] == 1 and report["outside"] == report["states"], report["line"]
    assert report["reason"] == "segment 0 (state 0): limits: locked joint panda_finger_joint1 = 5.0000 not in " \
        "[0.0000, 0.0400]"
    report = roadmap_check(_edited(roadmap, tmp_path / "r.npz", locked))
    assert report["status"] == 1 and "limits: locked joint panda_finger_joint1 = 5.0000" in report["reason"]


def test_check_path_refuses_another_kind_of_file(wall, tmp_path):
    sys.path.insert(0, str(EXAMPLES))
    from check_path import outside_check

    for kind in ("roadmap", "dataset"):
        report = outside_check(_edited(wall[0], tmp_path / "p.npz", set_key("kind", value=kind)))
        assert report["status"] == 3 and f"meta 'kind' is '{kind}', not 'path'" in report["line"], report["line"]


def test_roadmap_format_identity_arrays_and_edges_are_checked(wall, tmp_path):
    sys.path.insert(0, str(EXAMPLES))
    from check_roadmap import roadmap_check

    roadmap = wall[1]
    with np.load(roadmap) as f:
        nodes, edges = f["nodes"], f["edges"]

    def lengths(e):
        return np.linalg.norm(nodes[e[:, 1]] - nodes[e[:, 0]], axis=1)

    self_edge, swapped = edges.copy(), edges.copy()
    self_edge[2] = [4, 4]
    swapped[2] = swapped[2, ::-1]
    repeated = np.concatenate([edges, edges[1:2]])
    cases = [
        ({}, set_key("robot_identity", "urdf_sha256", value="0" * 64), "meta robot_identity urdf_sha256 000000000000 "
         "is not that of the robot files found"),
        ({}, set_key("robot_identity", "srdf_sha256", value="1" * 64), "meta robot_identity srdf_sha256 111111111111"),
        ({}, set_key("format_version", value=2), "meta 'format_version' is 2, not 1"),
        ({"edges": self_edge, "lengths": lengths(self_edge)}, None, "edge 2 [4, 4] joins node 4 to itself"),
        ({"edges": swapped, "lengths": lengths(swapped)}, None, f"edge 2 {swapped[2].tolist()} has its higher node "
         "first"),
        ({"edges": repeated, "lengths": lengths(repeated)}, None, f"edge {len(edges)} {edges[1].tolist()} repeats "
         "edge 1"),
        ({"edges": edges.astype(float)}, None, "edges are float64 "),
        ({"nodes": nodes.astype(np.float32)}, None, f"nodes are float32 {nodes.shape}, the format stores float64"),
    ]
    for arrays, edit, named in cases:
        report = roadmap_check(_edited(roadmap, tmp_path / "r.npz", edit, **arrays))
        assert report["status"] == 3 and named in report["line"], (named, report["line"])


def test_the_dataset_checker_refuses_a_negative_show(folder, datasets):
    path, _ = datasets["pose"]
    result = run(folder, "check_dataset.py", path, "--show", "-1")
    assert result.returncode == 2 and "--show must be 0 or more, got -1" in result.stderr, result.stderr
