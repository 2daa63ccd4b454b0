"""Hostile data and model files, reruns and resumes: each is refused in one line naming the problem and the fix,
and no file already written changes."""

from __future__ import annotations

import importlib.util
import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.data import collect
from manifoldgen.dataset import Dataset
from manifoldgen.errors import ManifoldgenError
from manifoldgen.models import CGAN, CVAE, open_model
from manifoldgen.tasks import BUILTIN_DIR, load_task_file
from manifoldgen.training import check_dataset, check_rows
from refusals import digest, reseal

TINY = {"hidden": [8], "batch": 8, "epochs": 1, "patience": 5}
EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def _save(path: Path, meta: dict, q: np.ndarray, y: np.ndarray, **extra) -> Path:
    np.savez(path, meta=json.dumps(meta), q=q, y=y, **extra)
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory, panda_task):
    """A dataset, its edited copies, a model and its edited (re-signed) copies, made once."""
    root = tmp_path_factory.mktemp("hostile_data")
    data = collect(panda_task, 12, seed=0, out=root / "data.npz", conditions=[[0.3], [0.5]], progress=False)
    meta, q, y = data.meta, data.q, data.y
    wall = json.loads((BUILTIN_DIR / "scenes" / "panda-wall.json").read_text())
    _save(root / "tolerance.npz", {**meta, "tolerance": [1e9] * 4}, q, y)
    _save(root / "robot.npz", {**meta, "robot": "pr2"}, q, y)
    _save(root / "names.npz", {**meta, "condition": {**meta["condition"], "names": ["banana"]}}, q, y)
    _save(root / "array.npz", meta, q, y, nodes=np.zeros(3))  # an array of another kind of file
    _save(root / "key.npz", {**meta, "robto": "panda"}, q, y)
    _save(root / "scene.npz", {**meta, "scenes": [{**wall, "obstacles": "x"}]}, q, y)
    CVAE(**TINY).fit(data, seed=0, progress=False, out=root / "model")
    reseal(shutil.copytree(root / "model", root / "pr2"), lambda d: d["meta"].__setitem__("robot", "pr2"))
    reseal(shutil.copytree(root / "model", root / "top"), lambda d: d.__setitem__("mixx", 0.5))
    reseal(shutil.copytree(root / "model", root / "foo"), lambda d: d["meta"].__setitem__("foo", 1))
    text = (BUILTIN_DIR / "pose-panda.toml").read_text().replace('"scenes/', f'"{BUILTIN_DIR}/scenes/')
    (root / "tight.toml").write_text(text.replace('position_axes = ["z"]\n',
                                                  'position_axes = ["z"]\nposition_tolerance = 1e-300\n'))
    return root


def _train(I, O, name, model=CVAE, seed=0):
    return model(**TINY).fit(Dataset.load(I / name), seed=seed, progress=False, out=O / "m")


def _collect_into(I, O, **kw):
    shutil.copy(I / "data.npz", O / "data.npz")
    return collect(_panda(), 12, **{"seed": 0, "out": O / "data.npz", "conditions": [[0.3], [0.5]],
                                    "progress": False, **kw})


def _retrain(I, O, **kw):
    shutil.copytree(I / "model", O / "m")
    return _train(I, O, "data.npz", **kw)


def _collect_over_text(I, O):
    (O / "t.npz").write_text("text")
    return collect(_panda(), 5, 0, O / "t.npz", progress=False)


def _select(data: Dataset, out: Path):
    """``train --model auto`` on ``data``: it reads the scenes it will race before it trains anything."""
    from manifoldgen.selection import select_model
    select_model(data, out, seed=0, epochs=1, progress=False)
    raise AssertionError("select_model trained")


def _tight_task(I):
    """The task of tight.toml, its tolerance below what projection reaches (as a constraint built in Python may be:
    task files refuse it)."""
    from manifoldgen.constraints import base
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(base, "MIN_TOLERANCE", 0.0)
        return load_task_file(I / "tight.toml")


def _panda():
    from manifoldgen.tasks import get_task
    return get_task("pose", "panda")


def _partial(I, O, **kw):
    """A collection interrupted with 12 rows at 0.3 and 0.5, rerun with other settings."""
    partial = O / "data.npz.partial"
    partial.mkdir()
    meta = json.loads(json.dumps(Dataset.load(I / "data.npz").meta))
    meta.pop("coverage")
    (partial / "meta.json").write_text(json.dumps({**meta, "conditions": [[0.3], [0.5]], "batch": 2048,
                                                   "max_batches": 1000, "give_up": 20}))
    np.savez(partial / "c0-b0.npz", meta="{}", q=np.zeros((1, 7)))
    return collect(_panda(), 12, out=O / "data.npz", progress=False, **kw)


@dataclass
class Case:
    id: str
    call: object  # call(I, O): I the inputs folder, O a fresh output folder
    needle: str


CASES = [
    Case("collect-over-other-dataset", lambda I, O: _collect_into(I, O, seed=1),
         "data.npz holds a dataset made with other settings (seed: 0 then, 1 now); choose another output (-o)"),
    Case("collect-over-other-conditions", lambda I, O: _collect_into(I, O, conditions=[[0.4]]),
         "(conditions: [[0.3], [0.5]] then, [[0.4]] now)"),
    Case("collect-over-a-non-dataset", _collect_over_text, "t.npz exists and was not written by manifoldgen"),
    Case("train-over-other-model", lambda I, O: _retrain(I, O, model=CGAN),
         'holds a finished model made with other settings (model: "cvae" then, "cgan" now;'),
    Case("train-over-other-seed", lambda I, O: _retrain(I, O, seed=2), "(seed: 0 then, 2 now)"),
    Case("dataset-tolerance-lie", lambda I, O: _train(I, O, "tolerance.npz"),
         "meta 'tolerance' contradicts its task (tolerance: [1000000000.0, 100000... in the file, [0.01, 0.01, "
         "0.01, 0.01] by its task)"),
    Case("dataset-robot-lie", lambda I, O: Dataset.load(I / "robot.npz"),
         "meta 'robot' \"pr2\" contradicts its task's \"panda\""),
    Case("dataset-condition-names-lie", lambda I, O: _train(I, O, "names.npz"),
         'condition.names: ["banana"] in the file, ["panda_hand_tcp.z"] by its task'),
    Case("dataset-extra-array", lambda I, O: Dataset.load(I / "array.npz"), "unknown array 'nodes' beside q and y"),
    Case("dataset-unknown-meta-key", lambda I, O: Dataset.load(I / "key.npz"),
         "unknown key 'robto' (did you mean 'robot'?)"),
    Case("dataset-scene-obstacles-not-a-list", lambda I, O: _select(Dataset.load(I / "scene.npz"), O / "m"),
         "the dataset's scenes[0]: 'obstacles' must be a list; the dataset was edited or is damaged: collect it"),
    Case("model-robot-lie", lambda I, O: open_model(I / "pr2"), "meta 'robot' \"pr2\" contradicts its task's"),
    Case("model-unknown-key", lambda I, O: open_model(I / "top"), "unknown key 'mixx' (did you mean 'mix'?)"),
    Case("model-unknown-meta-key", lambda I, O: open_model(I / "foo"), "meta has an unknown key 'foo'"),
    Case("collect-condition-twice", lambda I, O: collect(_panda(), 5, 0, conditions=[[0.3], [0.3]], progress=False),
         "condition value [0.3] is given twice; give each value once"),
    Case("collect-anchors-not-anchors", lambda I, O: collect(_panda(), 2, 0, conditions=[[0.3], [0.5]],
                                                             anchors="no", progress=False),
         "anchors must be query anchors (manifoldgen.scene.task_anchors) or None, got 'no'"),
    Case("collect-conditions-3d", lambda I, O: collect(_panda(), 2, 0, conditions=[[[0.3]], [[0.5]]], progress=False),
         "conditions must be condition values of shape (V, 1) (panda_hand_tcp.z per row), got shape (2, 1, 1)"),
    Case("task-tolerance-below-projection", lambda I, O: load_task_file(I / "tight.toml"),
         "position_tolerance must be at least 1e-05 (projection stops at a residual of 1e-6"),
    Case("collect-tolerance-too-tight", lambda I, O: collect(_tight_task(I), 5, 0, batch=64, give_up=1,
                                                             conditions=[[0.4]], progress=False),
         "[0.4] is inside panda_hand_tcp.z in [0.2, 0.7] m, but of 256 projected seeds 256 missed the tolerance "
         "(smallest 1e-300)"),
    Case("train-unconditioned", lambda I, O: check_rows(Dataset(np.zeros((20, 7)), np.zeros((20, 0)), {})),
         "dataset has no condition (its task is unconditioned); a conditional model needs one"),
    Case("collect-resume-other-settings", lambda I, O: _partial(I, O, seed=1, conditions=[[0.4]], anchors=None),
         "holds an interrupted collection made with other settings (seed: 0 then, 1 now; conditions: [[0.3], "
         "[0.5]] then, [[0.4]] now)"),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_hostile(case, files, tmp_path):
    before = digest(files)
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(ManifoldgenError) as info:
        case.call(files, out)
    message = str(info.value)
    assert case.needle in message, message
    assert "\n" not in message and len(message) < 400, message
    assert digest(files) == before
    assert not (out / "m" / "candidates").exists()


def test_a_refused_rerun_leaves_the_finished_output_as_it_was(files, tmp_path):
    shutil.copy(files / "data.npz", tmp_path / "data.npz")
    shutil.copytree(files / "model", tmp_path / "m")
    before = digest(tmp_path)
    with pytest.raises(ManifoldgenError, match="made with other settings"):
        collect(_panda(), 5, 0, tmp_path / "data.npz", conditions=[[0.4]], progress=False)
    with pytest.raises(ManifoldgenError, match="made with other settings"):
        CGAN(**TINY).fit(Dataset.load(files / "data.npz"), seed=0, progress=False, out=tmp_path / "m")
    assert digest(tmp_path) == before


def test_the_same_arguments_again_write_the_same_files(files, tmp_path):
    shutil.copy(files / "data.npz", tmp_path / "data.npz")
    shutil.copytree(files / "model", tmp_path / "m")
    before = digest(tmp_path)
    collect(_panda(), 12, 0, tmp_path / "data.npz", conditions=[[0.3], [0.5]], progress=False)
    CVAE(**TINY).fit(Dataset.load(files / "data.npz"), seed=0, progress=False, out=tmp_path / "m")
    after = digest(tmp_path)
    assert {k: v for k, v in after.items() if k.endswith(("npz", "safetensors", "model.json"))} == \
        {k: v for k, v in before.items() if k.endswith(("npz", "safetensors", "model.json"))}


def test_a_resume_with_other_settings_names_them(files, tmp_path, monkeypatch):
    def interrupted(*args, **kwargs):
        raise RuntimeError("killed")
    monkeypatch.setattr("manifoldgen.training.needed_refine", interrupted)  # dies after the last checkpoint
    data = Dataset.load(files / "data.npz")
    with pytest.raises(RuntimeError):
        CVAE(**TINY).fit(data, seed=0, epochs=2, progress=False, out=tmp_path / "kt")
    assert (tmp_path / "kt" / "checkpoint.safetensors").exists()
    for model, kw, needle in ((CVAE, {"seed": 1}, "(seed: 0 then, 1 now)"),
                              (CVAE, {"epochs": 3}, "(epochs: 2 then, 3 now)"),
                              (CVAE, {"hidden": [9]}, "(config.hidden: [8] then, [9] now)"),
                              (CGAN, {}, '(model: "cvae" then, "cgan" now;')):
        settings = {"seed": 0, "epochs": 2, **kw}
        with pytest.raises(ManifoldgenError) as info:
            model(**{**TINY, **{k: v for k, v in kw.items() if k == "hidden"}}).fit(
                data, seed=settings["seed"], epochs=settings["epochs"], progress=False, out=tmp_path / "kt",
                resume=True)
        assert needle in str(info.value) and "the checkpoint in" in str(info.value), str(info.value)


def test_the_dataset_checker_refuses_a_robot_its_task_contradicts(files):
    spec = importlib.util.spec_from_file_location("check_dataset", EXAMPLES / "check_dataset.py")
    checker = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(checker)
    report = checker.check(files / "robot.npz")
    assert report["status"] == 3 and "meta 'robot' pr2 contradicts its task's panda" in report["line"]
    assert "pose on panda" in checker.check(files / "data.npz")["line"]


def test_the_command_line_refuses_a_rerun_with_other_settings(files, tmp_path):
    shutil.copy(files / "data.npz", tmp_path / "data.npz")
    result = CliRunner().invoke(app, ["collect", "pose", "--per-condition", "5", "--condition", "0.4", "--seed", "1",
                                      "-o", str(tmp_path / "data.npz")], terminal_width=400)
    assert result.exit_code == 2 and "error: " in result.output and "choose another output (-o)" in result.output
    assert (tmp_path / "data.npz").read_bytes() == (files / "data.npz").read_bytes()


def test_a_dataset_that_contradicts_its_task_is_refused_by_check_dataset(files, panda_task):
    with pytest.raises(ManifoldgenError, match="meta 'tolerance' contradicts its task"):
        check_dataset(Dataset.load(files / "tolerance.npz"), panda_task)


def test_automatic_training_reuses_only_its_own_candidates(files, tmp_path):
    """``train --model auto`` reuses a finished candidate only when it was trained on the same rows, seed and epochs,
    and never writes its choice over a model trained alone."""
    from manifoldgen.selection import _check_reused, select_model

    data = Dataset.load(files / "data.npz")
    folder = tmp_path / "auto" / "candidates" / "cvae"
    folder.parent.mkdir(parents=True)
    CVAE(**TINY).fit(data, seed=0, progress=False, out=folder)
    _check_reused(folder, data, seed=0, epochs=1)  # this run's candidate: reused
    with pytest.raises(ManifoldgenError, match=r"holds a candidate trained with other settings \(seed: 0 then, 3 now"):
        _check_reused(folder, data, seed=3, epochs=1)
    with pytest.raises(ManifoldgenError, match=r"\(epochs: 1 then, 2 now\)"):
        _check_reused(folder, data, seed=0, epochs=2)
    alone = tmp_path / "alone"
    shutil.copytree(files / "model", alone)
    before = (alone / "model.json").read_bytes()
    with pytest.raises(ManifoldgenError, match="holds a model trained alone .no selection.json.; choose another"):
        select_model(data, alone, seed=0, epochs=1, progress=False)
    assert (alone / "model.json").read_bytes() == before and not (alone / "candidates").exists()
