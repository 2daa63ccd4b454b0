"""Task files: built-in tasks are files, tasks rebuild from file meta alone, bad task files are one clear line."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.errors import ManifoldgenError
from manifoldgen.scene import get_scene
from manifoldgen.settings import parse_settings
from manifoldgen.tasks import builtin_tasks, get_task, load_task_file, task_from_spec

runner = CliRunner()
GOOD = """\
name = "mine"
robot = "panda"
group = ["panda_joint1", "panda_joint2", "panda_joint3", "panda_joint4", "panda_joint5", "panda_joint6",
         "panda_joint7"]

[[constraints]]
type = "pose"
frame = "panda_hand_tcp"
rotation = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]
values = [[0.3], [0.5]]
"""


def test_builtin_tasks_are_files_and_rebuild_from_their_spec():
    assert set(builtin_tasks()["pose"]) == {"panda", "pr2", "centauro"}
    for robot in builtin_tasks()["pose"]:
        task = get_task("pose", robot)
        rebuilt = task_from_spec(json.loads(json.dumps(task.spec())))
        assert rebuilt.spec() == task.spec()
        q = task.robot.sample_uniform(5, np.random.default_rng(0))
        np.testing.assert_array_equal(rebuilt.constraint.residual(q, task.home_condition),
                                      task.constraint.residual(q, task.home_condition))
        assert task.constraint.satisfied(task.home, task.home_condition)[0]


def test_a_task_file_loads_like_a_builtin(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(GOOD)
    task = get_task(str(path))
    assert task.name == "mine" and task.robot.name == "panda" and task.condition.grid.tolist() == [[0.3], [0.5]]
    assert task.constraint.spec() == {**get_task("pose").constraint.spec(), "values": [[0.3], [0.5]]}
    result = runner.invoke(app, ["tasks", str(path)])
    assert result.exit_code == 0 and "mine" in result.output and "0.3; 0.5" in result.output


def test_a_task_files_planner_table_sets_defaults_that_set_overrides(tmp_path):
    from manifoldgen.query import run_query, task_settings

    path = tmp_path / "mine.toml"
    path.write_text(GOOD + "[planner]\nreach = 0.3\nrange = 1\n")
    task = get_task(str(path))
    assert task.planner == {"reach": 0.3, "range": 1.0} and task_from_spec(task.spec()).planner == task.planner
    assert task_settings(task, "rrtconnect", {"range": 0.7}) == {"reach": 0.3, "range": 0.7}
    assert task_settings(task, "rrt") == {"range": 1.0}  # RRT has no stepping stones
    sphere = get_task("sphere")  # its [planner] reach is in metres, fitted to the unit sphere
    result, meta = run_query(sphere, get_scene(sphere, "sphere"), "project", "rrtconnect", seed=0, time_limit=20)
    assert result.solved and meta["planner_settings"]["reach"] == 0.2 and meta["planner_settings"]["edges"] == "coarse:1"
    assert meta["task"]["planner"] == {"reach": 0.2, "edges": "coarse:1"}


BAD = [
    ("colour = 3\n" + GOOD, "line 1: unknown key 'colour'"),
    (GOOD.replace('type = "pose"', 'type = "posse"'), "line 6: constraint 1: unknown constraint 'posse'; did you mean pose"),
    (GOOD.replace('frame = "panda_hand_tcp"', 'frame = "hand"'), "line 6: constraint 1: unknown frame 'hand'"),
    (GOOD.replace('"panda_joint7"]', '"panda_joint77"]'), "line 3: unknown joint 'panda_joint77'"),
    (GOOD.replace('"panda_joint7"]', '"panda_joint7", "panda_joint7"]'), "panda_joint7"),
    (GOOD.replace('"panda_joint7"]', '"panda_hand_joint"]'), "panda_hand_joint"),
    (GOOD.replace('robot = "panda"', 'robot = "pandas"'), "line 2: unknown robot 'pandas'"),
    (GOOD.replace('type = "pose"', 'type = "no_such_module:Thing"'), "cannot import module 'no_such_module'"),
    (GOOD.replace('type = "pose"', 'type = "json:JSONDecoder"'), "is not a Constraint subclass"),
    (GOOD + "colour = 1\n", "line 6: constraint 1: constraint 'pose': got an unexpected keyword argument 'colour'"),
    (GOOD.replace("name = ", "nam = "), "unknown key 'nam'"),
    ("robot = [", "not valid TOML"),
    (GOOD + "[planner]\nreech = 0.2\n", "line 11: unknown planner setting 'reech' (did you mean 'reach'?)"),
    (GOOD + "[planner]\nreach = \"far\"\n", "line 11: planner setting reach must be a number"),
    # values of the wrong kind, refused when the file is read (not by a later command, not read letter by letter)
    (GOOD + "[planner]\nreach = -1.0\n", "line 11: reach must be a positive distance"),
    (GOOD + "[planner]\nedges = \"lazy\"\n", "line 11: edges must be 'coarse:K' or 'dense:K'"),
    ('default = "no"\n' + GOOD, "line 1: 'default' (this robot is the default for the task name) must be true or false"),
    ("floating_base = 0\n" + GOOD, "line 1: 'floating_base' (true for a free-flying base) must be true or false"),
    (GOOD.replace('name = "mine"', 'name = ["mine"]'), "line 1: 'name' (task name) must be a string"),
    (GOOD.replace('robot = "panda"', "robot = 5"), "line 2: 'robot' (example-robot-data name or URDF path) must be a string"),
    ('name = "mine"\nrobot = "panda"\ngroup = "panda_joint1"\n' + GOOD[GOOD.index("[[constraints]]"):],
     "line 3: 'group' (planning group joints) must be a list of joint names"),
    (GOOD.replace("values = [[0.3], [0.5]]", "values = [[0.3], [0.5]]\nposition_axes = \"xy\""),
     "constraint 'pose': position_axes must be a list"),
    (GOOD + "position_tolerance = nan\n", "constraint 'pose': position_tolerance must be a finite number, got nan"),
    (GOOD + "position_tolerance = -0.01\n", "constraint 'pose': position_tolerance must be at least 1e-05"),
    (GOOD + "position_tolerance = 1e-7\n", "position_tolerance must be at least 1e-05 (projection stops at a residual"),
    (GOOD + "orientation_tolerance = \"0.01\"\n",
     "constraint 'pose': orientation_tolerance must be a finite number (written without quotes), got '0.01'"),
    (GOOD.replace('frame = "panda_hand_tcp"', "frame = 3"), "constraint 'pose': frame must be a string, got 3"),
]


@pytest.mark.parametrize("text, message", BAD)
def test_bad_task_files_are_one_clear_line(text, message, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ManifoldgenError, match=None) as info:
        load_task_file(path)
    assert message in str(info.value) and "\n" not in str(info.value)
    result = runner.invoke(app, ["collect", str(path), "-o", str(tmp_path / "d.npz")])
    assert result.exit_code == 2 and message in result.output and "Traceback" not in result.output
    assert not (tmp_path / "d.npz").exists()


def test_end_effector_targets_become_configurations_on_one_branch(tmp_path):
    task = get_task("pose")
    scene = {"name": "t", "robot": "panda", "obstacles": [], "condition": [0.5],
             "start": {"position": [0.45, 0.3, 0.5]}, "goal": {"position": [0.4, -0.3, 0.5], "quaternion": [1, 0, 0, 0]}}
    (tmp_path / "t.json").write_text(json.dumps(scene))
    resolved = get_scene(task, str(tmp_path / "t.json"))
    for end, target in (("start", [0.45, 0.3, 0.5]), ("goal", [0.4, -0.3, 0.5])):
        q = getattr(resolved, end)
        assert task.constraint.satisfied(q, [0.5])[0]
        np.testing.assert_allclose(task.robot.frame_pose(q, "panda_hand_tcp")[0][0], target, atol=0.01)
    assert json.loads(resolved.to_json())["start"] == {"position": [0.45, 0.3, 0.5]}
    from manifoldgen.viewer.source import read_source
    shown = read_source(tmp_path / "t.json", "pose")  # the viewer resolves targets the same way
    np.testing.assert_allclose(shown.q, np.stack([resolved.start, resolved.goal]))
    (tmp_path / "far.json").write_text(json.dumps({**scene, "goal": {"position": [3.0, 0.0, 0.5]}}))
    with pytest.raises(ManifoldgenError, match="no collision-free configuration .* goal target"):
        get_scene(task, str(tmp_path / "far.json"))


def test_settings_are_checked_against_the_known_keys(tmp_path):
    known = {"lr": 1e-3, "hidden": [256, 256], "epochs": 60, "spectral": False}
    assert parse_settings(["lr=1", "hidden=[64,64]", "spectral=true"], None, known, "cvae") == \
        {"lr": 1.0, "hidden": [64, 64], "spectral": True}
    (tmp_path / "c.toml").write_text("epochs = 5\nlr = 0.01\n")
    assert parse_settings(["lr=0.1"], tmp_path / "c.toml", known, "cvae") == {"epochs": 5, "lr": 0.1}
    with pytest.raises(ManifoldgenError, match="unknown cvae setting 'width'; known: epochs, hidden, lr, spectral"):
        parse_settings(["width=3"], None, known, "cvae")
    with pytest.raises(ManifoldgenError, match="epochs must be a whole number"):
        parse_settings(["epochs=fast"], None, known, "cvae")
    with pytest.raises(ManifoldgenError, match="is not KEY=VALUE"):
        parse_settings(["epochs"], None, known, "cvae")


def test_registries_read_entry_points_and_module_class_names(monkeypatch):
    """A package announces a constraint through the manifoldgen.constraints entry point group."""
    from manifoldgen import registry
    from manifoldgen.constraints import CONSTRAINTS, JointLinearConstraint

    class EntryPoint:
        name, value = "coupled", "some_package:Coupled"

        def load(self):
            return JointLinearConstraint

    class Installed:  # what importlib.metadata.entry_points() gives: every group's, selected by group
        def select(self, group):
            return [EntryPoint()] if group == "manifoldgen.constraints" else []

    monkeypatch.setattr(registry, "_entry_points", Installed)
    monkeypatch.setattr(CONSTRAINTS, "_classes", dict(CONSTRAINTS._classes))
    monkeypatch.setattr(CONSTRAINTS, "_entry_points", None)
    assert "coupled" not in CONSTRAINTS.names(announced=False)  # what --help lists: the package's own only
    assert "coupled" in CONSTRAINTS.names() and CONSTRAINTS.get("coupled") is JointLinearConstraint
    assert CONSTRAINTS.get("manifoldgen.constraints.plane:PlaneConstraint").__name__ == "PlaneConstraint"
    with pytest.raises(ManifoldgenError, match="unknown constraint 'coupld'; did you mean coupled"):
        CONSTRAINTS.get("coupld")


def test_a_module_imported_from_another_folder_is_refused_not_reused(tmp_path):
    """Two task files whose folders each hold a module of one name: in one process the second is refused in one line
    (Python would reuse the first's module), naming both files."""
    example = Path(__file__).resolve().parents[1] / "examples" / "user_task"
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "shadowed_tool.py").write_text((example / "tool_down.py").read_text())
        (tmp_path / folder / "task.toml").write_text((example / "tool-down-xarm7.toml").read_text().replace(
            "tool_down:ToolDownAtX", "shadowed_tool:ToolDownAtX").split("[scenes]")[0])
    first = load_task_file(tmp_path / "a" / "task.toml")
    assert sys.modules[type(first.constraint).__module__].__file__ == str(tmp_path / "a" / "shadowed_tool.py")
    with pytest.raises(ManifoldgenError, match=f"module shadowed_tool is already imported in this process from "
                                               f"{tmp_path / 'a' / 'shadowed_tool.py'}, not from the task file's folder "
                                               f"\\({tmp_path / 'b' / 'shadowed_tool.py'}\\)"):
        load_task_file(tmp_path / "b" / "task.toml")
    assert load_task_file(tmp_path / "a" / "task.toml").name == "tool-down"  # its own folder's module: accepted
