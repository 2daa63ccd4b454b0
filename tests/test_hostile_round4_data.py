"""Hostile dataset and model files, and training outputs: a meta value of the wrong kind or range, an unknown key in
a meta's task, anchors of the wrong length, narrowed arrays, a path or roadmap given as a dataset, a folder of the
user's files given as a model directory. Each is refused in one line naming the problem and the fix, before anything
is written, and no file already there changes."""

from __future__ import annotations

import copy
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from manifoldgen.data import collect
from manifoldgen.dataset import TASK_SPEC_KEYS, Dataset
from manifoldgen.errors import ManifoldgenError, differences
from manifoldgen.io import save_npz
from manifoldgen.models import CVAE, load_model
from manifoldgen.sampling import sample_to_file
from manifoldgen.tasks import task_from_meta
from manifoldgen.training import check_dataset
from refusals import api, cli, refused_as_told, reseal

TINY = {"hidden": [8], "batch": 8, "epochs": 1, "patience": 5}
USER_FILES = {"training.json": "{\"mine\": 1}", "loss.png": "my plot", "other.txt": "notes"}


def _edited(root: Path, name: str, edit, q=None) -> None:
    """``root/name.npz``: the dataset ``root/data.npz`` with its meta changed by ``edit(meta)`` (and ``q``)."""
    data = Dataset.load(root / "data.npz")
    meta = json.loads(json.dumps(data.meta))
    edit(meta)
    np.savez(root / f"{name}.npz", meta=json.dumps(meta), q=data.q if q is None else q, y=data.y)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, panda_task, planned_path):
    """A dataset, its edited copies, a model and its edited (re-signed) copy, a path, a roadmap and a folder of the
    user's files, made once."""
    root = tmp_path_factory.mktemp("round4_data")
    data = collect(panda_task, 12, seed=0, out=root / "data.npz", conditions=[[0.3], [0.5]], progress=False)
    short_anchor = [{"label": "wall start", "q": [0.1, 0.2, 0.3], "condition": [0.5]}]
    for name, edit in (("anchor-short", lambda m: m.update(anchors=short_anchor)),
                       ("seed-negative", lambda m: m.update(seed=-5)),
                       ("rows-text", lambda m: m.update(per_condition="many")),
                       ("coverage-text", lambda m: m.update(coverage="garbage")),
                       ("method-null", lambda m: m.update(method=None)),
                       ("near-home-huge", lambda m: m.update(near_home=1e308)),
                       ("rate-above-one", lambda m: m.update(raw_valid_rate=1.5)),
                       ("task-extra-key", lambda m: m["task"].update(foo=1)),
                       ("task-misspelt-key", lambda m: m["task"].update(hom=m["task"].pop("home"))),
                       ("values-extra", lambda m: m["condition"]["values"].append([0.95])),
                       ("task-home-short", lambda m: m["task"].update(home=[0.1, 0.2])),
                       ("task-home-off", lambda m: m["task"]["home"].__setitem__(1, m["task"]["home"][1] + 0.3)),
                       ("task-floating-text", lambda m: m["task"].update(floating_base="no")),
                       ("task-group-text", lambda m: m["task"].update(group="panda_joint1"))):
        _edited(root, name, edit)
    _edited(root, "q-float32", lambda m: None, q=data.q.astype(np.float32))
    CVAE(**TINY).fit(data, seed=0, progress=False, out=root / "model")
    reseal(shutil.copytree(root / "model", root / "anchor-model"),
           lambda d: d["meta"].__setitem__("anchors", short_anchor))
    shutil.copy(planned_path("wall"), root / "path.npz")
    save_npz(root / "rm.npz", {"kind": "roadmap"}, nodes=np.zeros((2, 7)))
    (root / "userdir").mkdir()
    for name, text in USER_FILES.items():
        (root / "userdir" / name).write_text(text)
    return root


def _off_limits(I):
    """check_dataset of the dataset with row 0 moved 1e-6 rad past panda_joint1's upper limit."""
    data = Dataset.load(I / "data.npz")
    task = task_from_meta(data.meta)
    q = data.q.copy()
    q[0, 0] = task.robot.upper[0] + 1e-6
    check_dataset(Dataset(q, data.y, data.meta), task)


CASES = [
    cli("train-anchor-q-short", "train {I}/anchor-short.npz --model cvae -o {O}/m",
        "meta anchors[0] must hold a 'label', its configuration 'q' (a number per joint: 7) and its 'condition' (a "
        "number per condition column: 1)"),
    cli("sample-model-anchor-q-short", "sample {I}/anchor-model --condition 0.4 -o {O}/s.npz",
        "anchor-model/model.json: meta anchors[0] must hold a 'label', its configuration 'q' (a number per joint: 7)"),
    cli("train-seed-negative", "train {I}/seed-negative.npz --model cvae -o {O}/m",
        "meta 'seed' -5 must be a whole number from 0 to 4294967295"),
    cli("train-per-condition-text", "train {I}/rows-text.npz --model cvae -o {O}/m",
        "meta 'per_condition' \"many\" must be a positive whole number"),
    cli("train-coverage-text", "train {I}/coverage-text.npz --model cvae -o {O}/m",
        "meta 'coverage' \"garbage\" must be an object {\"modes\""),
    cli("train-method-null", "train {I}/method-null.npz --model cvae -o {O}/m", "meta 'method' null must be a string"),
    api("dataset-near-home-huge", lambda I, O: Dataset.load(I / "near-home-huge.npz"),
        "meta 'near_home' 1e+308 must be a number from 0 to 10 (rad)"),
    api("dataset-rate-above-one", lambda I, O: Dataset.load(I / "rate-above-one.npz"),
        "meta 'raw_valid_rate' 1.5 must be a share from 0 to 1"),
    cli("train-task-extra-key", "train {I}/task-extra-key.npz --model cvae -o {O}/m",
        "meta 'task' has an unknown key 'foo'; the file was edited or is damaged"),
    api("dataset-task-misspelt-key", lambda I, O: Dataset.load(I / "task-misspelt-key.npz"),
        "meta 'task' has an unknown key 'hom' (did you mean 'home'?)"),
    api("dataset-task-home-short", lambda I, O: Dataset.load(I / "task-home-short.npz"),
        "meta task 'home' [0.1, 0.2] must hold a number per joint (7)"),
    api("dataset-task-floating-text", lambda I, O: Dataset.load(I / "task-floating-text.npz"),
        "meta task 'floating_base' \"no\" must be true or false"),
    api("dataset-task-group-text", lambda I, O: Dataset.load(I / "task-group-text.npz"),
        "meta task 'group' \"panda_joint1\" must be a list of joint names"),
    cli("export-dataset-per-condition-text", "view {I}/rows-text.npz --export {O}/x.html",
        "meta 'per_condition' \"many\" must be a positive whole number"),
    cli("export-dataset-q-float32", "view {I}/q-float32.npz --export {O}/x.html", "q is float32"),
    cli("train-task-home-off", "train {I}/task-home-off.npz --model cvae -o {O}/m",
        "its task's home is off its constraint (projecting it moves a joint"),
    cli("train-on-a-path", "train {I}/path.npz -o {O}/m",
        "path.npz is a path file, not a dataset: give a dataset written by `manifoldgen collect`"),
    cli("train-on-a-roadmap", "train {I}/rm.npz -o {O}/m",
        "rm.npz is a roadmap file, not a dataset: give a dataset written by `manifoldgen collect`"),
    cli("train-condition-values-extra", "train {I}/values-extra.npz --model cvae -o {O}/m",
        "(condition.values: 7 items in the file, 6 items by its task (the first 6 alike))"),
    cli("train-q-float32", "train {I}/q-float32.npz --model cvae -o {O}/m",
        "q-float32.npz: q is float32, which rounds rows off the constraint and past the joint limits; store q and y "
        "as float64 (what collect writes)"),
    api("check-dataset-row-off-limits", lambda I, O: _off_limits(I),
        "dataset row 0 does not satisfy its task's constraint (joint panda_joint1 is 1e-06 outside its limits "
        "[-2.8973, 2.8973]); 1 of 24 rows checked fail"),
    cli("collect-near-home-huge", "collect pose --near-home 1e308 --per-condition 5 -o {O}/x.npz",
        "near_home must be a standard deviation from 0 to 10 rad"),
    api("collect-near-home-above-bound", lambda I, O: collect(task_from_meta(Dataset.load(I / "data.npz").meta), 5,
                                                              0, O / "x.npz", near_home=10.5, progress=False),
        "near_home must be a standard deviation from 0 to 10 rad (0: uniform seeds; wider ones pile the rows at"),
    cli("train-into-the-users-folder", "train {I}/data.npz --model cvae -o {I}/userdir",
        "userdir holds loss.png, other.txt, training.json but no model.json nor checkpoint.safetensors, so it is not a "
        "model directory; train into a new or empty folder (-o)"),
    api("fit-into-the-users-folder", lambda I, O: CVAE(**TINY).fit(Dataset.load(I / "data.npz"), seed=0,
                                                                  progress=False, out=I / "userdir"),
        "userdir holds loss.png, other.txt, training.json but no model.json nor checkpoint.safetensors"),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_round4_data(case, inputs, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    refused_as_told(case, inputs, out)


def test_a_sample_file_reads_back_as_a_dataset(inputs, tmp_path):
    """What sample writes besides a dataset's meta (its seed, rows, refine, source, rates) meets the meta checks."""
    model = load_model(inputs / "model")
    sample_to_file(model, task_from_meta(model.meta).constraint, np.array([0.4]), 5, tmp_path / "s.npz")
    meta = Dataset.load(tmp_path / "s.npz").meta
    assert meta["rows"] == "refined" and meta["dataset_seed"] == 0 and 0 <= meta["raw_valid_rate"] <= 1


def test_training_into_an_empty_folder_or_one_with_a_killed_writers_leftover(inputs, tmp_path):
    (tmp_path / "empty").mkdir()
    (tmp_path / "left").mkdir()
    (tmp_path / "left" / ".checkpoint.safetensors.99999-x1.tmp").write_bytes(b"half")
    for folder in ("empty", "left"):
        CVAE(**TINY).fit(Dataset.load(inputs / "data.npz"), seed=0, progress=False, out=tmp_path / folder)
        assert (tmp_path / folder / "model.json").is_file() and (tmp_path / folder / "training.json").is_file()


def test_the_task_keys_a_meta_takes_are_those_a_task_spec_writes(panda_task):
    task = copy.copy(panda_task)
    task.attached, task.planner = {"name": "cup"}, {"planner": "rrtconnect"}  # the keys written only when set
    assert set(task.spec()) == set(TASK_SPEC_KEYS)


@pytest.mark.parametrize("old, new, shown", [
    ([[0.2], [0.3], [0.4], [0.5], [0.6], [0.7]], [[0.2], [0.3], [0.4], [0.5], [0.6], [0.7], [0.95]],
     "values: 6 items then, 7 items now (the first 6 alike)"),
    (list(range(20)), [*range(19), 99], "values[19]: 19 then, 99 now"),
    ([[0.123456789] * 3, [1.0, 2.0]], [[0.123456789] * 3, [1.0, 2.5]], "values[1]: [1.0, 2.0] then, [1.0, 2.5] now"),
    ([1, 2], [1, 3], "values: [1, 2] then, [1, 3] now"),
])
def test_differences_show_where_lists_that_look_alike_differ(old, new, shown):
    assert differences(old, new, "values") == shown


def test_a_file_where_collect_keeps_its_batches_is_named(panda_task, tmp_path):
    (tmp_path / "d.npz.partial").write_text("mine")
    with pytest.raises(ManifoldgenError, match=r"d.npz.partial is a file where collect keeps the batches of an "
                                               r"unfinished run \(a folder\); move or delete it"):
        collect(panda_task, 5, 0, tmp_path / "d.npz", conditions=[[0.4]], progress=False)
    assert (tmp_path / "d.npz.partial").read_text() == "mine" and not (tmp_path / "d.npz").exists()


def test_a_sample_file_and_a_dataset_never_replace_each_other(inputs, tmp_path):
    """Both are .npz files of rows: samples never replace a collected dataset, and Dataset.save writes .npz only."""
    model = load_model(inputs / "model")
    constraint = task_from_meta(model.meta).constraint
    shutil.copy(inputs / "data.npz", tmp_path / "data.npz")
    before = (tmp_path / "data.npz").read_bytes()
    with pytest.raises(ManifoldgenError, match="holds a dataset file, which this samples file would replace"):
        sample_to_file(model, constraint, np.array([0.4]), 5, tmp_path / "data.npz")
    assert (tmp_path / "data.npz").read_bytes() == before
    with pytest.raises(ManifoldgenError, match=r"must end in .npz, got .*d.txt"):
        Dataset.load(inputs / "data.npz").save(tmp_path / "d.txt")
    sample_to_file(model, constraint, np.array([0.4]), 5, tmp_path / "s.npz")
    sample_to_file(model, constraint, np.array([0.4]), 5, tmp_path / "s.npz")  # samples over samples: as before


def test_a_sweep_never_writes_into_a_folder_of_someone_elses_files(inputs, tmp_path):
    from manifoldgen.model_sweep import sweep
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "training.json").write_text("mine")
    with pytest.raises(ManifoldgenError, match="mine holds training.json but no model.json nor sweep.json nor "
                                               "candidates"):
        sweep(Dataset.load(inputs / "data.npz"), tmp_path / "mine", models=["cvae"], latents=[2], seeds=[0],
              epochs=1, progress=False)
    assert [p.name for p in (tmp_path / "mine").iterdir()] == ["training.json"]


@pytest.mark.parametrize("task, robot", [("pose", "panda"), ("balance", "centauro"), ("dualarm", "pr2")])
def test_every_shipped_kind_of_task_spec_passes_the_meta_checks(task, robot):
    """The task spec checks take what Task.spec writes: six base bounds of a floating base, locked joints."""
    from manifoldgen.dataset import check_meta
    from manifoldgen.tasks import get_task

    t = get_task(task, robot)
    check_meta({"format_version": 2, **t.meta()}, t.condition.k, "dataset")
