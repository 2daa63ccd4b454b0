"""Collection and the dataset file: validity row by row, determinism, resume, bad files."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import manifoldgen.data as data_module
from manifoldgen.collision import CollisionChecker
from manifoldgen.data import collect
from manifoldgen.dataset import Dataset
from manifoldgen.errors import ManifoldgenError

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def small(panda_task, tmp_path_factory):
    path = tmp_path_factory.mktemp("data") / "pose.npz"
    return collect(panda_task, 40, 3, path, batch=256, progress=False), path


def test_every_row_is_valid_and_meta_is_complete(panda_task, small):
    dataset, _ = small
    assert dataset.q.shape == (240, 7) and dataset.y.shape == (240, 1)
    assert panda_task.constraint.satisfied(dataset.q, dataset.y).all()
    assert not CollisionChecker(panda_task.robot).in_collision(dataset.q).any()
    np.testing.assert_allclose(np.unique(dataset.y), [0.2, 0.3, 0.4, 0.5, 0.6, 0.7])
    meta = dataset.meta
    assert meta["robot"] == "panda" and meta["joints"] == [f"panda_joint{i}" for i in range(1, 8)]
    assert meta["constraint"]["type"] == "pose" and meta["seed"] == 3 and meta["format_version"] == 2
    assert set(meta["locked"]) == {"panda_finger_joint1", "panda_finger_joint2"}


def test_file_round_trip_and_independent_checker(small):
    dataset, path = small
    loaded = Dataset.load(path)
    np.testing.assert_array_equal(loaded.q, dataset.q)
    np.testing.assert_array_equal(loaded.y, dataset.y)
    assert loaded.meta == json.loads(json.dumps(dataset.meta))
    out = subprocess.run([sys.executable, str(ROOT / "examples" / "check_dataset.py"), str(path)],
                         capture_output=True, text=True, check=True).stdout
    assert "240 rows" in out and "all three 100.00%" in out


def test_same_seed_same_dataset_and_other_seed_differs(panda_task, small):
    dataset, _ = small
    again = collect(panda_task, 40, 3, batch=256, progress=False)
    np.testing.assert_array_equal(again.q, dataset.q)
    other = collect(panda_task, 40, 4, batch=256, progress=False)
    assert not np.allclose(other.q, dataset.q)


def test_interrupted_collection_resumes_to_the_same_file(panda_task, small, tmp_path, monkeypatch):
    dataset, _ = small
    path = tmp_path / "resumed.npz"
    real_draw, calls = data_module.draw_batch, []

    def draw_then_die(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real_draw(*args, **kwargs)

    monkeypatch.setattr(data_module, "draw_batch", draw_then_die)
    with pytest.raises(KeyboardInterrupt):
        collect(panda_task, 40, 3, path, batch=256, progress=False)
    partial = tmp_path / "resumed.npz.partial"
    assert len(list(partial.glob("c*-b*.npz"))) == 2 and not path.exists()
    calls.clear()
    monkeypatch.setattr(data_module, "draw_batch", lambda *a, **k: (calls.append(1), real_draw(*a, **k))[1])
    resumed = collect(panda_task, 40, 3, path, batch=256, progress=False)
    np.testing.assert_array_equal(resumed.q, dataset.q)
    assert not partial.exists() and path.exists()
    assert len(calls) == 6 - 2  # 256-row batches give > 40 valid rows: one batch per condition, 2 were saved


def test_bad_collection_arguments(panda_task, tmp_path):
    with pytest.raises(ManifoldgenError, match="positive"):
        collect(panda_task, 0, 0, progress=False)
    with pytest.raises(ManifoldgenError, match="does not exist"):
        collect(panda_task, 5, 0, tmp_path / "missing" / "x.npz", progress=False)
    with pytest.raises(ManifoldgenError, match="unreachable"):
        collect(panda_task, 5, 0, conditions=[[1.5]], batch=64, give_up=2, progress=False)


def test_truncated_foreign_and_nan_files_are_refused(small, tmp_path):
    _, path = small
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(path.read_bytes()[:500])
    with pytest.raises(ManifoldgenError, match="truncated"):
        Dataset.load(truncated)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, a=np.zeros(3))
    with pytest.raises(ManifoldgenError, match="not a manifoldgen file"):
        Dataset.load(foreign)
    d = Dataset.load(path)
    d.q[0, 0] = np.nan
    with pytest.raises(ManifoldgenError, match=r"nan.npz \(not written\): contains NaN or infinite values"):
        d.save(tmp_path / "nan.npz")  # our writer refuses it; a file written by other means is refused on reading
    assert not (tmp_path / "nan.npz").exists()
    from manifoldgen.io import save_npz
    save_npz(tmp_path / "nan.npz", d.meta, q=d.q, y=d.y)
    with pytest.raises(ManifoldgenError, match="NaN"):
        Dataset.load(tmp_path / "nan.npz")
    with pytest.raises(ManifoldgenError, match="not found"):
        Dataset.load(tmp_path / "absent.npz")


@pytest.mark.parametrize("change, words", [
    ({"format_version": 1}, "dataset format 1 is not the one this version reads (2)"),
    ({"format_version": "2"}, "dataset format '2' is not the one"),
    ({"joints": "panda_joint1"}, "'joints' a list of joint names"),
    ({"robot": ["panda"]}, "meta 'robot' must be a name"),
])
def test_a_dataset_of_another_format_or_with_a_malformed_meta_is_refused(tmp_path, change, words):
    from manifoldgen.dataset import FORMAT_VERSION, Dataset

    joints = [f"panda_joint{i}" for i in range(1, 8)]
    meta = {"format_version": FORMAT_VERSION, "robot": "panda", "joints": joints, "constraint": {"type": "pose"}}
    from manifoldgen.io import save_npz

    save_npz(tmp_path / "d.npz", {**meta, **change}, q=np.zeros((3, 7)), y=np.zeros((3, 1)))
    with pytest.raises(ManifoldgenError) as error:
        Dataset.load(tmp_path / "d.npz")
    assert words in str(error.value) and "\n" not in str(error.value)
    with pytest.raises(ManifoldgenError, match="not written") as error:  # what no reader takes is not written
        Dataset(np.zeros((3, 7)), np.zeros((3, 1)), {**meta, **change}).save(tmp_path / "e.npz")
    assert words in str(error.value) and not (tmp_path / "e.npz").exists()
