"""Determinism: the same seed and thread count give the same bytes for collect, train and sample, and the
same path for plan (whose file also records how long planning took: only those timing fields differ)."""

from __future__ import annotations

from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.data import collect
from manifoldgen.io import load_npz
from manifoldgen.models import pretrained_model_dir

runner = CliRunner()
TIMING = {"time_s"}  # seconds measured while planning (README: "Reliability")


def _run(*args: str) -> None:
    result = runner.invoke(app, list(args))
    assert result.exit_code == 0, result.output


def test_collect_twice_same_bytes(panda_task, tmp_path):
    for name in ("a.npz", "b.npz"):
        collect(panda_task, 8, 11, tmp_path / name, conditions=[[0.4], [0.6]], progress=False)
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()


def test_train_twice_same_bytes(panda_task, tmp_path):
    collect(panda_task, 20, 2, tmp_path / "d.npz", conditions=[[0.3], [0.5]], progress=False)
    for name in ("a", "b"):
        _run("train", str(tmp_path / "d.npz"), "--model", "cvae", "--set", "hidden=[8]", "--set", "batch=8", "--epochs", "2",
             "--seed", "4", "--threads", "1", "-o", str(tmp_path / name))
    for name in ("model.json", "model.safetensors"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name


def test_sample_twice_same_bytes(tmp_path):
    for name in ("a.npz", "b.npz"):
        _run("sample", str(pretrained_model_dir()), "--condition", "0.45", "-n", "300", "--seed", "9",
             "-o", str(tmp_path / name))
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()


def _without_timing(value):
    if isinstance(value, dict):
        return {k: _without_timing(v) for k, v in value.items() if k not in TIMING}
    return [_without_timing(v) for v in value] if isinstance(value, list) else value


def test_plan_twice_same_path(planned_path, tmp_path):
    first = planned_path("wall")  # planned with this command, seed 0
    _run("plan", "pose", "--robot", "panda", "--scene", "wall", "--sampler", f"cvae:{pretrained_model_dir()}",
         "--seed", "0", "--time", "60", "-o", str(tmp_path / "p.npz"))
    (meta_a, a), (meta_b, b) = load_npz(first, ("path",)), load_npz(tmp_path / "p.npz", ("path",))
    assert a["path"].tobytes() == b["path"].tobytes() and len(a["path"]) > 1
    assert _without_timing(meta_a) == _without_timing(meta_b)
