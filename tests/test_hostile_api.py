"""The Python API and the path-file reader under hostile input: a task given by name where a task is expected, path
files whose meta disagrees with their path or their task (reversed joints, a start or goal that is not the path's
ends, unknown arrays and meta keys), sampler options out of range, a scene of another task, arguments of the wrong
type. Each refusal is one short line naming the argument (not a command-line option) and the fix; no input changes."""

from __future__ import annotations


import numpy as np
import pytest

import manifoldgen as mg
from manifoldgen.data import collect
from manifoldgen.dataset import Dataset
from manifoldgen.io import load_npz, save_npz
from manifoldgen.models import CVAE
from manifoldgen.query import PATH_KEYS, read_path_file
from manifoldgen.tasks import BUILTIN_DIR, get_task
from refusals import api, cli, refused_cleanly

TINY = {"hidden": [8], "batch": 8, "epochs": 1, "patience": 5}
SHORT = 300  # characters a refusal may take at most


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, panda_task, planned_path):
    """A folder made once: a dataset, a tiny model, a planned path and path files edited after planning."""
    root = tmp_path_factory.mktemp("inputs")
    data = collect(panda_task, 12, seed=0, conditions=[[0.3], [0.5]], progress=False)
    data.save(root / "data.npz")
    Dataset(data.q, data.y, {**data.meta, "joints": data.meta["joints"][::-1]}).save(root / "reversed-data.npz")
    CVAE(**TINY).fit(data, seed=0, progress=False, out=root / "model")
    (root / "folder").mkdir()
    meta, arrays = load_npz(planned_path("wall"), ("path",))
    path = arrays["path"]
    save_npz(root / "path.npz", meta, path=path)
    edits = {"reversed": {"joints": meta["joints"][::-1]}, "start-moved": {"start": [0.0] * len(meta["start"])},
             "goal-moved": {"goal": (np.asarray(meta["goal"]) + 1e-3).tolist()},
             "start-text": {"start": "home"}, "start-short": {"start": meta["start"][:3]},
             "unknown-key": {"sceen": []}, "joints-short": {"joints": meta["joints"][:2]},
             "tolerance-long": {"tolerance": [1e9] * 500}}
    for name, change in edits.items():
        save_npz(root / f"{name}.npz", {**meta, **change}, path=path)
    save_npz(root / "extra-array.npz", meta, path=path, nodes=np.zeros(3))  # an array of another kind of file
    return root


def _pose_pr2():
    return get_task("pose", "pr2")


CASES = [
    # a task given by name or file to QueryResult.load, then checked against the file
    api("load-task-name-of-another-task", lambda I, O: mg.QueryResult.load(I / "path.npz", task="dualarm"),
        "path.npz was made for another task: robot panda"),
    api("load-task-of-another-robot", lambda I, O: mg.QueryResult.load(I / "path.npz", task=_pose_pr2()),
        "7 joints vs 8"),
    api("load-task-number", lambda I, O: mg.QueryResult.load(I / "path.npz", task=3),
        "QueryResult.load: task must be a Task (mg.load_task) or a task name or task .toml file, got int 3"),
    api("load-task-unknown-name", lambda I, O: mg.QueryResult.load(I / "path.npz", task="poze"), "'poze'"),
    api("load-trust-code-text", lambda I, O: mg.QueryResult.load(I / "path.npz", trust_code="yes"),
        "QueryResult.load: trust_code must be True or False, got str 'yes'"),
    # path files whose meta an outside checker would find false: refused by every reader
    cli("trajectory-reversed-joints", "trajectory {I}/reversed.npz -o {O}/t.json",
        "meta 'joints' are not its pose task's joints: column 0 \"panda_joint7\" vs panda_joint1; column 1 "
        "\"panda_joint6\" vs panda_joint2; column 2 \"panda_joint5\" vs panda_joint3 (and 3 more)"),
    cli("trajectory-start-moved", "trajectory {I}/start-moved.npz -o {O}/t.json",
        "the path does not start at the recorded start (meta 'start')"),
    cli("view-goal-moved", "view {I}/goal-moved.npz --export {O}/v.html",
        "the path does not end at the recorded goal (meta 'goal'): 0.001 rad apart"),
    api("load-start-moved", lambda I, O: mg.QueryResult.load(I / "start-moved.npz"), "does not start at the recorded"),
    api("load-start-text", lambda I, O: mg.QueryResult.load(I / "start-text.npz"),
        'meta \'start\' must be 7 finite numbers, got "home"'),
    api("load-start-short", lambda I, O: mg.QueryResult.load(I / "start-short.npz"), "meta 'start' must be 7 finite"),
    api("load-joints-short", lambda I, O: read_path_file(I / "joints-short.npz"),
        'meta \'joints\' are not its pose task\'s joints: ["panda_joint1", "panda_joint2"] vs 7 names'),
    api("load-tolerance-long", lambda I, O: read_path_file(I / "tolerance-long.npz"),
        "meta 'tolerance' [1000000000.0, 1000000000.0, 10000000... is not its task's [0.01, "),
    cli("trajectory-extra-array", "trajectory {I}/extra-array.npz -o {O}/t.json",
        'unknown array "nodes"; a path file holds only \'path\' and \'meta\''),
    cli("trajectory-unknown-meta-key", "trajectory {I}/unknown-key.npz -o {O}/t.json",
        'unknown meta key "sceen" (did you mean \'scene\'?)'),
    # sampler options: the same ranges whether given as arguments or in the spec string
    api("sampler-model-batch-zero", lambda I, O: mg.sampler("pose", "wall", mg.load_model(I / "model"), batch=0),
        "sampler: batch must be from 1 to 100,000, got 0"),
    api("sampler-spec-batch-zero", lambda I, O: mg.sampler("pose", "wall", "project", batch=0),
        "sampler: batch must be from 1 to 100,000, got 0"),
    api("sampler-model-refine-huge", lambda I, O: mg.sampler("pose", "wall", mg.load_model(I / "model"), refine=5000),
        "sampler: refine must be from 0 to 1,000, got 5000"),
    api("sampler-dataset-refine", lambda I, O: mg.sampler("pose", "wall", Dataset.load(I / "data.npz"), refine=2),
        "sampler: refine applies to a model's samples"),
    api("sampler-model-of-another-robot", lambda I, O: mg.sampler(_pose_pr2(), "wall", mg.load_model(I / "model")),
        "the model was made for another task: robot panda"),
    api("sampler-dataset-reversed-joints",
        lambda I, O: mg.sampler("pose", "wall", Dataset.load(I / "reversed-data.npz")),
        'joints "panda_joint7" vs panda_joint1, "panda_joint6" vs panda_joint2, "panda_joint5" vs panda_joint3 (and 3 more)'),
    # a Scene object of another robot or task
    api("plan-scene-of-another-robot", lambda I, O: mg.plan("pose", mg.load_scene("dualarm", "tray-over")),
        "plan: scene 'tray-over' is for robot pr2, task pose for panda; load the scene for this task"),
    api("check-path-scene-of-another-task",
        lambda I, O: mg.check_path(_pose_pr2(), mg.load_scene("dualarm", "tray-over"), np.zeros((2, 8))),
        "check_path: scene 'tray-over' was loaded for another task (start has 15, goal has 15, condition has 2 "
        "values; task pose on pr2 takes 8 joint values and 1 condition value(s))"),
    api("sampler-scene-of-another-task", lambda I, O: mg.sampler(_pose_pr2(), mg.load_scene("dualarm", "tray-over")),
        "sampler: scene 'tray-over' was loaded for another task"),
    # arguments are named as the API names them, not as command-line options
    api("train-zero-epochs", lambda I, O: mg.train(I / "data.npz", "cvae", epochs=0),
        "train: epochs must be a positive number"),
    api("train-auto-negative-epochs", lambda I, O: mg.train(I / "data.npz", epochs=-2),
        "train: epochs must be a positive number"),
    api("collect-zero-rows", lambda I, O: mg.collect("pose", 0), "collect: per_condition must be a positive number"),
    api("save-into-a-folder", lambda I, O: mg.QueryResult.load(I / "path.npz").save(I / "folder"),
        "QueryResult.save: file"),
]


def test_the_table_has_unique_ids():
    assert len({c.id for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_hostile_api_input(case, inputs, tmp_path):
    message = refused_cleanly(case, inputs, tmp_path)
    assert case.needle in message, message
    assert len(message) <= SHORT + len(str(inputs)), message
    assert "--" not in message or case.args is not None, message  # the API names its arguments
    assert not list(tmp_path.iterdir()), "a refused command wrote something"


def test_a_path_file_loads_with_its_task_by_name_or_file_and_keeps_its_keys(inputs):
    """QueryResult.load takes the task as a Task, a name or a task file; a planned path's meta holds only the keys
    a path file may hold, and its ends are its recorded start and goal."""
    by_name = mg.QueryResult.load(inputs / "path.npz", task="pose")
    by_file = mg.QueryResult.load(inputs / "path.npz", task=BUILTIN_DIR / "pose-panda.toml")
    plain = mg.QueryResult.load(inputs / "path.npz")
    np.testing.assert_array_equal(by_name.path, plain.path)
    np.testing.assert_array_equal(by_file.path, plain.path)
    assert set(plain.meta) <= set(PATH_KEYS) and {"start", "goal", "joints"} <= set(plain.meta)
    np.testing.assert_array_equal(plain.path[0], plain.meta["start"])
    np.testing.assert_array_equal(plain.path[-1], plain.meta["goal"])


def test_a_path_without_start_and_goal_is_read(inputs, tmp_path):
    """The start and goal are checked where the meta records them (an outside checker's rule): a file written
    without them is read."""
    meta, arrays = load_npz(inputs / "path.npz", ("path",))
    bare = {k: v for k, v in meta.items() if k not in ("start", "goal")}
    save_npz(tmp_path / "bare.npz", bare, path=arrays["path"])
    assert read_path_file(tmp_path / "bare.npz")[1].shape == arrays["path"].shape


def test_a_saved_query_result_loads_back(inputs, tmp_path):
    """QueryResult.save writes a path file QueryResult.load reads back unchanged (its ends, its keys)."""
    loaded = mg.QueryResult.load(inputs / "path.npz")
    again = mg.QueryResult.load(loaded.save(tmp_path / "again.npz"))
    np.testing.assert_array_equal(again.path, loaded.path)
    assert again.meta == loaded.meta
