"""``manifoldgen plan``: path files rechecked by an outside checker (pinocchio + coal, the file
alone), and one clear error per bad input."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.data import collect
from manifoldgen.errors import ManifoldgenError
from manifoldgen.models import CVAE
from manifoldgen.scene import get_scene
from manifoldgen.tasks import get_task

runner = CliRunner()
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
sys.path.insert(0, str(EXAMPLES))
from check_path import outside_check  # noqa: E402  (the standalone checker users run)


@pytest.mark.slow
@pytest.mark.parametrize("robot,scene,seed", [("panda", "wall", 0), ("panda", "wall", 1), ("panda", "maze", 0),
                                              ("pr2", "wall", 0)])
def test_plan_writes_a_path_that_an_outside_checker_accepts(tmp_path, robot, scene, seed):
    out = tmp_path / "p.npz"
    result = runner.invoke(app, ["plan", "pose", "--robot", robot, "--scene", scene, "--sampler", "project",
                                 "--planner", "rrtconnect", "--seed", str(seed), "--time", "60", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "solved in" in result.output and "waypoints" in result.output
    check = outside_check(out)
    assert check["worst"] <= 1.0 and check["collisions"] == 0 and check["outside"] == 0
    assert check["states"] > len(check["path"])
    meta = check["meta"]
    assert meta["robot"] == robot and len(meta["joints"]) == len(check["path"][0])
    assert meta["condition"] == ([0.5] if robot == "panda" else [0.8])
    assert meta["result"]["solved"] and meta["validation"]["valid"]
    assert (out.with_suffix(".png")).stat().st_size > 10_000
    if scene == "maze":
        assert meta["scene"][-1]["attached_to"] == "panda_hand_tcp"


def test_plan_with_sbl_and_the_shipped_cvae_passes_the_outside_checker(tmp_path):
    from manifoldgen.models import pretrained_model_dir
    out = tmp_path / "sbl.npz"
    result = runner.invoke(app, ["plan", "pose", "--robot", "panda", "--scene", "wall", "--sampler",
                                 f"cvae:{pretrained_model_dir()}", "--planner", "sbl", "--seed", "0", "--time", "60",
                                 "-o", str(out)])
    assert result.exit_code == 0, result.output
    check = outside_check(out)
    assert check["worst"] <= 1.0 and check["collisions"] == 0 and check["outside"] == 0
    assert check["states"] > len(check["path"]) and check["meta"]["result"]["planner"] == "sbl"
    assert check["meta"]["result"]["extras"]["lazy"]["edges_checked"] > 0


def test_outside_checker_catches_a_path_through_the_wall(tmp_path, panda_task):
    """The checker itself must see collisions and constraint violations."""
    out = tmp_path / "p.npz"
    runner.invoke(app, ["plan", "pose", "--scene", "wall", "--sampler", "project", "--time", "60", "-o", str(out)])
    data = np.load(out)
    meta = json.loads(str(data["meta"]))
    straight = np.stack([data["path"][0], data["path"][-1]])
    np.savez(tmp_path / "bad.npz", meta=np.array(json.dumps(meta)), path=straight)
    check = outside_check(tmp_path / "bad.npz")
    assert check["worst"] > 1.0 or check["collisions"] > 0


def _plan(tmp_path, *args):
    base = {"--scene": "wall", "--sampler": "project", "--planner": "rrtconnect", "--time": "5"}
    for key, value in zip(args[::2], args[1::2]):
        base[key] = value
    argv = ["plan", "pose", "--robot", "panda", "-o", str(tmp_path / "p.npz")]
    for key, value in base.items():
        argv += [key, value]
    return runner.invoke(app, argv)


def _scene_file(tmp_path, panda_task, **change) -> str:
    data = json.loads(get_scene(panda_task, "wall").to_json())
    data.update(change)
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(data))
    return str(path)


def test_bad_start_and_goal_say_by_how_much_and_which_link(tmp_path, panda_task):
    wall = get_scene(panda_task, "wall")
    off = _scene_file(tmp_path, panda_task, start=(wall.start + [0, 0.2, 0, 0, 0, 0, 0]).tolist())
    result = _plan(tmp_path, "--scene", off)
    assert result.exit_code == 2
    assert "start configuration violates the constraint: residual component" in result.output
    assert "times its tolerance" in result.output
    hand = panda_task.robot.frame_pose(wall.goal, "panda_hand")[0][0].tolist()
    blocked = json.loads(wall.to_json())["obstacles"] + [{"name": "crate", "type": "box", "size": [0.1, 0.1, 0.1],
                                                          "pose": {"position": hand, "quaternion": [0, 0, 0, 1]}}]
    result = _plan(tmp_path, "--scene", _scene_file(tmp_path, panda_task, obstacles=blocked))
    assert result.exit_code == 2 and "goal configuration is in collision: " in result.output
    assert "panda_hand_0 with crate" in result.output and "choose a collision-free goal" in result.output


def test_bad_scene_file_time_and_planner(tmp_path, panda_task):
    cone = json.loads(get_scene(panda_task, "wall").to_json())["obstacles"]
    cone[0]["type"] = "cone"
    result = _plan(tmp_path, "--scene", _scene_file(tmp_path, panda_task, obstacles=cone))
    assert result.exit_code == 2 and "unknown type 'cone'" in result.output and "known types" in result.output
    cone[0].update(type="box", size=[0.4, 0.0, 0.6])
    result = _plan(tmp_path, "--scene", _scene_file(tmp_path, panda_task, obstacles=cone))
    assert result.exit_code == 2 and "must be three positive extents" in result.output
    result = _plan(tmp_path, "--time", "0")
    assert result.exit_code == 2 and "--time must be from 0.001 to 86400, got 0" in result.output
    result = _plan(tmp_path, "--planner", "rrtconect")
    assert result.exit_code == 2
    assert "unknown planner 'rrtconect'; did you mean rrtconnect? known planners: rrtconnect, rrt, prm, kpiece, " \
           "cbirrt" in result.output
    result = _plan(tmp_path, "--local", "spline")
    assert result.exit_code == 2 and "unknown local planner 'spline'" in result.output


def test_bad_sampler_specs(tmp_path, panda_task):
    result = _plan(tmp_path, "--sampler", f"cvae:{tmp_path / 'nowhere'}")
    assert result.exit_code == 2 and "no trained model at" in result.output and "manifoldgen train" in result.output
    result = _plan(tmp_path, "--sampler", "gan:x")
    assert result.exit_code == 2 and "unknown model 'gan'" in result.output
    result = _plan(tmp_path, "--sampler", "random")
    assert result.exit_code == 2 and "unknown sampler 'random'" in result.output
    result = _plan(tmp_path, "--sampler", "project,refine=2")
    assert result.exit_code == 2 and "takes no refine option" in result.output
    pr2 = collect(get_task("pose", "pr2"), 40, seed=0, conditions=[[0.7], [0.8]], progress=False)
    CVAE(hidden=[16], batch=32).fit(pr2, epochs=1, seed=0, progress=False, out=tmp_path / "pr2model")
    result = _plan(tmp_path, "--sampler", f"cvae:{tmp_path / 'pr2model'}")
    assert result.exit_code == 2 and "made for another task: robot pr2" in result.output and "vs panda" in result.output
    result = _plan(tmp_path, "--sampler", f"cgan:{tmp_path / 'pr2model'}")
    assert result.exit_code == 2 and "holds a cvae model, not cgan" in result.output
    pr2.save(tmp_path / "pr2.npz")
    result = _plan(tmp_path, "--sampler", f"pg:{tmp_path / 'pr2.npz'}")
    assert result.exit_code == 2 and "dataset" in result.output and "made for another task: robot pr2" in result.output


def test_an_unsolved_plan_writes_nothing_and_says_why(tmp_path):
    out = tmp_path / "p.npz"
    result = runner.invoke(app, ["plan", "pose", "--scene", "maze", "--time", "0.001", "-o", str(out)])
    assert result.exit_code == 1, result.output
    assert "not solved" in result.output and "nothing written" in result.output
    assert not out.exists() and not out.with_suffix(".png").exists()


BROKEN_PATHS = [  # (what is changed in a planned path file, the words of the one-line refusal)
    ("format", lambda meta, path: ({**meta, "format_version": 99}, path), "path format 99 is not the one"),
    ("no format", lambda meta, path: ({k: v for k, v in meta.items() if k != "format_version"}, path), "format null"),
    ("kind", lambda meta, path: ({**meta, "kind": "dataset"}, path), 'its meta says kind "dataset"'),
    ("empty", lambda meta, path: (meta, path[:0]), "must be a non-empty (K, n) float64 array of finite numbers"),
    ("NaN", lambda meta, path: (meta, np.where(np.arange(path.size).reshape(path.shape) == 3, np.nan, path)),
     "must be a non-empty (K, n) float64 array of finite numbers"),
    ("strings", lambda meta, path: (meta, path.astype(str)),
     "must be a non-empty (K, n) float64 array of finite numbers"),
    ("float32", lambda meta, path: (meta, path.astype(np.float32)), "got float32 of shape"),
    ("width", lambda meta, path: (meta, path[:, :5]), "its states have 5 coordinates"),
    ("condition", lambda meta, path: ({**meta, "condition": ["high"]}, path), "meta 'condition' must be 1 finite"),
    ("no condition", lambda meta, path: ({k: v for k, v in meta.items() if k != "condition"}, path),
     "meta 'condition' must be 1 finite"),
]


@pytest.mark.parametrize("change, words", [(c, w) for _, c, w in BROKEN_PATHS], ids=[i for i, _, _ in BROKEN_PATHS])
def test_a_path_file_is_checked_whole_before_it_is_used(planned_path, tmp_path, change, words):
    """Every reader of path files (trajectory, snapshots, the viewer, physics) refuses a broken one in one line
    before using it (read_path_file); the trajectory command says it and writes nothing."""
    from manifoldgen.io import load_npz, save_npz
    from manifoldgen.query import read_path_file

    meta, arrays = load_npz(planned_path("wall"), ("path",))
    meta, path = change(meta, arrays["path"])
    broken = tmp_path / "broken.npz"
    save_npz(broken, meta, path=path)
    with pytest.raises(ManifoldgenError) as error:
        read_path_file(broken)
    assert words in str(error.value) and "\n" not in str(error.value)
    result = runner.invoke(app, ["trajectory", str(broken), "-o", str(tmp_path / "t.csv")])
    assert result.exit_code == 2 and words in result.output and not (tmp_path / "t.csv").exists()


def test_no_picture_writes_the_path_alone(tmp_path):
    out = tmp_path / "p.npz"
    result = runner.invoke(app, ["plan", "pose", "--scene", "wall", "--sampler", "project", "--no-picture",
                                 "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.npz"] and result.output.rstrip().endswith(str(out))
