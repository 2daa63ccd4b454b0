"""Hostile files beside and inside outputs: a lock that is a link or someone's file, an archive holding an array no
manifoldgen file holds, a partial folder of someone else's files, a damaged checkpoint or candidate log, rows that
contradict their meta, a condition grid too large to build, model configs of the wrong kind. Each is refused in one
line before anything is written, and no file already there changes."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import safetensors.numpy

from manifoldgen import io
from manifoldgen.data import collect
from manifoldgen.dataset import Dataset
from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import save_npz
from manifoldgen.models import CVAE
from manifoldgen.tasks import BUILTIN_DIR
from refusals import api, cli, edited_npz, refused_as_told, refused_cleanly, reseal, set_key

TINY = {"hidden": [8], "batch": 8, "epochs": 1, "patience": 5}


def _checkpoint(root: Path, name: str, edit) -> None:
    """``root/name``: the interrupted training ``root/cut`` with its checkpoint's tensors and state edited by
    ``edit(arrays, state)``."""
    shutil.copytree(root / "cut", root / name)
    blob = (root / "cut" / "checkpoint.safetensors").read_bytes()
    header = json.loads(blob[8:8 + int.from_bytes(blob[:8], "little")])["__metadata__"]
    arrays, state = safetensors.numpy.load(blob), json.loads(header["state"])
    edit(arrays, state)
    (root / name / "checkpoint.safetensors").write_bytes(
        safetensors.numpy.save(arrays, metadata={**header, "state": json.dumps(state)}))


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A dataset and its edited copies, an interrupted training and its damaged checkpoints, an automatic training
    with a damaged candidate log, a model with a config of the wrong kind, locks that are not ours."""
    root = tmp_path_factory.mktemp("round5_data")
    data = collect(__import__("manifoldgen.tasks", fromlist=["get_task"]).get_task("pose", "panda"), 12, seed=0,
                   out=root / "data.npz", conditions=[[0.3], [0.5]], progress=False)
    meta = json.loads(json.dumps(data.meta))
    save_npz(root / "junk.npz", meta, q=data.q, y=data.y, junk=np.zeros(5_000_000))  # 40 MB of zeros, compressed
    save_npz(root / "per-condition.npz", {**meta, "per_condition": 7}, q=data.q, y=data.y)
    (root / "victim.txt").write_text("precious")
    os.symlink(root / "victim.txt", root / "linked.npz.lock")
    (root / "mine.npz.lock").write_text("my notes on this lock")
    (root / "p.npz.partial").mkdir()
    (root / "p.npz.partial" / "notes.txt").write_text("mine")

    def interrupted(self, *args, calls=[0], original=CVAE._train_step):
        calls[0] += 1
        if calls[0] == 5:
            raise KeyboardInterrupt
        return original(self, *args)

    CVAE._train_step, step = interrupted, CVAE._train_step
    try:
        with pytest.raises(ManifoldgenError, match="--resume"):
            CVAE(**TINY).fit(data, epochs=4, seed=0, progress=False, out=root / "cut")
    finally:
        CVAE._train_step = step
    _checkpoint(root, "ck-no-rng", lambda a, s: a.pop("rng"))
    _checkpoint(root, "ck-bad-text", lambda a, s: s.update(bad="x"))
    _checkpoint(root, "ck-no-optimizers", lambda a, s: s.pop("optimizers"))
    CVAE(**TINY).fit(data, seed=0, progress=False, out=root / "model")
    (root / "userdir").mkdir()
    (root / "userdir" / "keep.txt").write_text("mine")
    (root / "linked-auto").mkdir()
    os.symlink(root / "userdir", root / "linked-auto" / "candidates")
    (root / "homec-nested.toml").write_text((BUILTIN_DIR / "pose-panda.toml").read_text().replace(
        "home_condition = [0.45]", "home_condition = [[0.45]]").replace('"scenes/', f'"{BUILTIN_DIR}/scenes/'))
    reseal(shutil.copytree(root / "model", root / "lr-text"), lambda d: d["config"].__setitem__("lr", "fast"))
    return root


RESUME = ("train {I}/data.npz --model cvae --epochs 4 --set hidden=[8] --set batch=8 --set patience=5 --set epochs=1 "
          "--resume -o {O}/m")

CASES = [
    cli("lock-is-a-link", "collect pose --per-condition 5 --condition 0.3 --condition 0.4 -o {I}/linked.npz",
        "linked.npz.lock, where -o {I}/linked.npz keeps its lock, is a symbolic link; remove it"),
    cli("lock-is-a-users-file", "collect pose --per-condition 5 --condition 0.3 --condition 0.4 -o {I}/mine.npz",
        "mine.npz.lock, where -o {I}/mine.npz keeps its lock, is a file manifoldgen did not write; move or delete it"),
    cli("an-array-no-file-holds", "train {I}/junk.npz --model cvae -o {O}/m",
        "junk.npz is not a manifoldgen file: it holds an array \"junk\", which none holds (read without loading it)"),
    cli("partial-folder-of-a-users-files", "collect pose --per-condition 5 --condition 0.3 -o {I}/p.npz",
        "p.npz.partial holds files collect did not write (notes.txt); it keeps the batches of an unfinished run there"),
    cli("per-condition-contradicts-rows", "train {I}/per-condition.npz --model cvae -o {O}/m",
        "meta 'per_condition' 7 but 12 rows at condition [0.3]; the file was edited"),
    cli("model-config-lr-text", "plan pose --scene wall --sampler cvae:{I}/lr-text --no-picture -o {O}/p.npz",
        "config \"lr\" is \"fast\", not a finite number or a list of widths"),
    api("dataset-save-rows-mismatch",
        lambda I, O: Dataset(np.zeros((3, 7)), np.zeros((2, 1)), Dataset.load(I / "data.npz").meta).save(O / "d.npz"),
        "d.npz (not written): inconsistent shapes q (3, 7), y (2, 1) for 7 joints"),
    cli("auto-candidates-a-link", "train {I}/data.npz --epochs 1 -o {I}/linked-auto",
        "linked-auto/candidates is a symbolic link; train writes its candidates into folders of its own"),
    cli("pg-with-refine", "plan pose --scene wall --sampler pg:{I}/data.npz,refine=3 --no-picture -o {O}/p.npz",
        "the pg sampler takes no refine option"),
    cli("bench-model-beside-methods", "bench plan pose --scene wall --runs 1 -m rrtconnect@project --model {I}/model "
        "-o {O}/b", "with -m, name the model in a method"),
    cli("home-condition-nested", "tasks {I}/homec-nested.toml",
        "home_condition must be a flat list of numbers (no strings or booleans), got [[0.45]]"),
    api("collect-condition-a-bool",
        lambda I, O: collect(__import__("manifoldgen.tasks", fromlist=["get_task"]).get_task("pose"), 3, 0,
                             conditions=[[True], [0.3]], progress=False),
        "conditions must be condition values (V, 1) as numbers, got true"),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_round5_data(case, inputs, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    refused_as_told(case, inputs, out)


@pytest.mark.parametrize("name, why", [("ck-no-rng", "KeyError"), ("ck-bad-text", "ValueError"),
                                       ("ck-no-optimizers", "KeyError")])
def test_a_damaged_checkpoint_is_refused_in_one_line(inputs, tmp_path, name, why):
    shutil.copytree(inputs / name, tmp_path / "m")
    case = cli(name, RESUME.replace("{O}/m", str(tmp_path / "m")), "is damaged")
    message = refused_cleanly(case, inputs, tmp_path)
    assert f"checkpoint.safetensors is damaged ({why}" in message and "train from scratch" in message, message


def test_the_interrupted_training_itself_resumes(inputs, tmp_path):
    shutil.copytree(inputs / "cut", tmp_path / "m")
    log = CVAE(**TINY).fit(Dataset.load(inputs / "data.npz"), epochs=4, seed=0, progress=False, out=tmp_path / "m",
                           resume=True)
    assert log.resumed_at > 0 and len(log.history) == 4


def test_a_damaged_candidate_log_is_refused_when_its_training_is_reused(inputs, tmp_path):
    from manifoldgen.cli import app
    from refusals import runner

    args = ["train", str(inputs / "data.npz"), "--epochs", "1", "-o", str(tmp_path / "auto")]
    assert runner.invoke(app, args).exit_code == 0
    log = tmp_path / "auto" / "candidates" / "cvae" / "training.json"
    doc = json.loads(log.read_text())
    log.write_text(json.dumps({k: v for k, v in doc.items() if k != "history"}))
    result = runner.invoke(app, args)
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    assert "training.json is damaged (not the log training writes); delete the folder" in result.stderr


def test_a_grid_too_large_to_build_is_refused_at_once(panda_task):
    from manifoldgen.constraints import ConstraintSet, JointLinearConstraint

    row = [[0.0] * 6 + [1.0]]
    part = JointLinearConstraint(panda_task.robot, row, [[v] for v in np.linspace(-1, 1, 300)])
    with pytest.raises(ManifoldgenError, match=r"make 27,000,000 combinations \(the product of 300 x 300 x 300\)"):
        ConstraintSet([part, part, part])


def test_an_archive_larger_than_any_file_is_refused_from_its_directory(inputs, monkeypatch):
    monkeypatch.setattr(io, "MAX_NPZ_BYTES", 1000)
    with pytest.raises(ManifoldgenError, match=r"data.npz would take 0.0 GiB once read, over the 0 GiB"):
        Dataset.load(inputs / "data.npz")


def test_a_path_whose_meta_miscounts_its_waypoints_is_refused(planned_path, tmp_path):
    from manifoldgen.query import read_path_file

    edited_npz(planned_path("wall"), tmp_path / "p.npz", set_key("result", "waypoints", value=999))
    with pytest.raises(ManifoldgenError, match=r"meta 'result' gives 999 waypoints of length .*, but the path has"):
        read_path_file(tmp_path / "p.npz")


def test_a_bench_record_with_a_key_bench_does_not_write_is_refused():
    from manifoldgen.bench.planning import record_problem

    record = {"method": "m", "spec": "rrtconnect@project", "run": 0, "seed": 0, "scene": "wall", "time_limit": 1.0,
              "solved": False, "planner_solved": False, "valid": False, "time_s": 1.0, "length": 0.0,
              "iterations": 0, "samples_drawn": 0, "projections": 0, "waypoints": 0}
    assert record_problem(record) == ""
    assert record_problem({**record, "vaild": True}) == 'an unknown key "vaild"'


def test_roadmap_edges_are_listed_once_lower_node_first(tmp_path):
    from manifoldgen.planning.roadmap import _arrays

    meta = {"joints": ["a", "b"]}
    nodes = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    for edges in ([[1, 0]], [[0, 1], [0, 1]]):
        edges = np.array(edges, np.int64)
        lengths = np.linalg.norm(nodes[edges[:, 1]] - nodes[edges[:, 0]], axis=1)
        with pytest.raises(ManifoldgenError, match="must list each edge once, its lower node first"):
            _arrays(tmp_path / "rm.npz", meta, {"nodes": nodes, "edges": edges, "lengths": lengths})
    assert len(_arrays(tmp_path / "rm.npz", meta, {"nodes": nodes, "edges": np.array([[0, 1], [1, 2]]),
                                                   "lengths": np.array([1.0, 1.0])})[1]) == 2


def test_a_pose_without_position_axes_and_condition_rows_of_the_wrong_width_say_so(panda_task):
    from manifoldgen.constraints.base import Condition
    from manifoldgen.constraints.pose import PoseConstraint

    with pytest.raises(ManifoldgenError, match=r"pose needs at least one of position_axes"):
        PoseConstraint(panda_task.robot, "panda_hand_tcp", np.eye(3), [[0.3]], position_axes=[])
    with pytest.raises(ManifoldgenError, match=r"values rows must hold 2 number\(s\) \(x, y\), got 1$"):
        Condition(("x", "y"), ("m", "m"), [[0.3], [0.4], [0.5]])
    with pytest.raises(ManifoldgenError, match=r"must be 2 number\(s\) per row \(x, y\), got \[0.3, 0.4, 0.5\]$"):
        Condition(("x", "y"), ("m", "m"), [0.3, 0.4, 0.5])


def test_a_mesh_that_is_a_device_is_named_as_one():
    from manifoldgen.shapes import Obstacle

    with pytest.raises(ManifoldgenError, match=r"mesh file '/dev/zero' is not a regular file"):
        Obstacle.from_dict({"name": "m", "type": "mesh", "mesh": "/dev/zero", "pose": {"position": [0, 0, 0]}})


def test_a_path_whose_planner_settings_leave_their_ranges_is_refused(planned_path, tmp_path):
    from manifoldgen.query import read_path_file

    edited_npz(planned_path("wall"), tmp_path / "p.npz", set_key("planner_settings", "range", value=-1.0))
    with pytest.raises(ManifoldgenError, match=r"planner setting range must be a number in \[0.0001, 100\], got -1.0"):
        read_path_file(tmp_path / "p.npz")


def test_a_user_constraints_own_tolerance_is_held_to_the_built_in_range(tmp_path):
    from manifoldgen.tasks import load_task_file

    (tmp_path / "wide_tool.py").write_text(
        "import numpy as np\nfrom manifoldgen.constraints.base import Condition, Constraint\n\n\n"
        "class WideTool(Constraint):\n    def __init__(self, robot, values):\n        self.robot = robot\n"
        "        self.condition = Condition(('z',), ('m',), np.asarray(values, float))\n"
        "        self.tolerance = np.array([1e6])\n\n    def residual(self, q, y):\n        q, y = self.batch(q, y)\n"
        "        return self.robot.frame_pose(q, 'panda_hand_tcp')[0][:, 2:3] - y\n")
    (tmp_path / "wide.toml").write_text(
        'name = "wide"\nrobot = "panda"\ngroup = [' + ", ".join(f'"panda_joint{i}"' for i in range(1, 8)) + "]\n\n"
        '[[constraints]]\ntype = "wide_tool:WideTool"\nvalues = [[0.3], [0.5]]\n')
    with pytest.raises(ManifoldgenError, match=r"its tolerances must be positive and finite, from 1e-05 to 1 .*got \[1000000.0\]"):
        load_task_file(tmp_path / "wide.toml")
