"""Reliability regressions: resume settings, output permissions, the one-file checkpoint, the
collision-matrix cache, outputs that are inputs, and benchmark workers that die with their parent."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

import manifoldgen.io
from manifoldgen import collision
from manifoldgen.data import collect
from manifoldgen.dataset import Dataset
from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import atomic_write_text, check_output_path
from manifoldgen.models import CVAE

SRC = str(Path(__file__).resolve().parents[1] / "src")
TINY = {"hidden": [8], "batch": 8, "patience": 50}


def _interrupt_at(monkeypatch, module, name: str, call: int):
    """Make the ``call``-th call of ``module.name`` raise KeyboardInterrupt (an interrupted process)."""
    original, count = getattr(module, name), {"n": 0}

    def wrapped(*args, **kwargs):
        count["n"] += 1
        if count["n"] == call:
            raise KeyboardInterrupt
        return original(*args, **kwargs)
    monkeypatch.setattr(module, name, wrapped)


# ---------------------------------------------------------------------------------------- collect resume
def test_resume_with_other_settings_is_refused_naming_them(panda_task, tmp_path, monkeypatch):
    import manifoldgen.data as data
    import manifoldgen.dataset as dataset
    whole = tmp_path / "whole.npz"
    collect(panda_task, 6, seed=3, out=whole, conditions=[[0.3], [0.5]], batch=16, progress=False)
    out = tmp_path / "cut.npz"
    _interrupt_at(monkeypatch, dataset, "save_npz", 1)  # writing the dataset, after its two batches
    with pytest.raises(KeyboardInterrupt):
        collect(panda_task, 6, seed=3, out=out, conditions=[[0.3], [0.5]], batch=16, progress=False)
    monkeypatch.undo()
    partial = tmp_path / "cut.npz.partial"
    assert len(list(partial.glob("c*-b*.npz"))) == 2
    for change, named in (({"conditions": [[0.3], [0.6]]}, "conditions: [[0.3], [0.5]] then, [[0.3], [0.6]] now"),
                          ({"seed": 4}, "seed: 3 then, 4 now"), ({"per_condition": 7}, "per_condition: 6 then, 7 now"),
                          ({"batch": 32}, "batch: 16 then, 32 now")):
        args = {"per_condition": 6, "seed": 3, "conditions": [[0.3], [0.5]], "batch": 16, **change}
        with pytest.raises(ManifoldgenError, match="other settings") as info:
            collect(panda_task, args.pop("per_condition"), out=out, progress=False, **args)
        assert named in str(info.value)
        assert len(list(partial.glob("c*-b*.npz"))) == 2  # a refused resume keeps the batches
    from manifoldgen.tasks import get_task
    with pytest.raises(ManifoldgenError, match="task.robot.name: \"panda\" then, \"pr2\" now"):
        collect(get_task("pose", "pr2"), 6, seed=3, out=out, conditions=[[0.7], [0.8]], batch=16, progress=False)
    first = partial / "c0-b0.npz"  # a saved batch replaced by rows of another condition is recomputed
    data.save_npz(first, {}, q=collect(panda_task, 3, seed=8, conditions=[[0.6]], progress=False).q)
    collect(panda_task, 6, seed=3, out=out, conditions=[[0.3], [0.5]], batch=16, progress=False)
    assert out.read_bytes() == whole.read_bytes() and not partial.exists()


def test_failed_collect_leaves_no_partial_folder(panda_task, tmp_path):
    out = tmp_path / "x.npz"
    with pytest.raises(ManifoldgenError, match="unreachable"):
        collect(panda_task, 5, seed=0, out=out, conditions=[[3.0]], batch=8, give_up=2, progress=False)
    assert not out.exists() and not (tmp_path / "x.npz.partial").exists()


# ---------------------------------------------------------------------------------------- permissions
def test_a_failed_write_removes_the_folders_it_created(tmp_path, monkeypatch):
    """A model saved into a new folder on a full disk leaves no empty folder behind."""
    import io as stdio

    class Full(stdio.FileIO):
        def write(self, data):
            raise OSError(28, "No space left on device")
    monkeypatch.setattr("manifoldgen.io.os.fdopen", lambda fd, mode="wb": Full(fd, "wb"))
    (tmp_path / "kept").mkdir()
    with pytest.raises(ManifoldgenError, match="No space left"):
        atomic_write_text(tmp_path / "kept" / "new" / "deeper" / "model.json", "{}")
    assert [p.name for p in tmp_path.rglob("*")] == ["kept"]


@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_written_files_respect_the_umask(tmp_path, umask, mode, panda_task):
    old = os.umask(umask)
    try:
        atomic_write_text(tmp_path / "a.txt", "x")
        Dataset(panda_task.home[None], panda_task.home_condition[None], {"format_version": 2, **panda_task.meta()}
                ).save(tmp_path / "d.npz")
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == mode
    assert (tmp_path / "d.npz").stat().st_mode & 0o777 == mode


# ---------------------------------------------------------------------------------------- outputs vs inputs
def test_outputs_never_overwrite_inputs(tmp_path):
    model = tmp_path / "model"
    model.mkdir()
    (model / "model.json").write_text("{}")
    data = tmp_path / "d.npz"
    data.write_text("x")
    with pytest.raises(ManifoldgenError, match="model.json, part of the input folder"):
        check_output_path(model / "model.json", [model])
    with pytest.raises(ManifoldgenError, match="would overwrite the input"):
        check_output_path(tmp_path / "." / "d.npz", [data])
    os.symlink(data, tmp_path / "link.npz")
    with pytest.raises(ManifoldgenError, match="would overwrite the input"):
        check_output_path(tmp_path / "link.npz", [data])
    with pytest.raises(ManifoldgenError, match="is the input folder"):
        check_output_path(model, [model], directory=True)
    with pytest.raises(ManifoldgenError, match="would overwrite the input"):
        check_output_path(tmp_path, [data], directory=True, writes=["d.npz"])
    with pytest.raises(ManifoldgenError, match="a folder is meant"):
        check_output_path(data, directory=True)
    with pytest.raises(ManifoldgenError, match="a file is meant"):
        check_output_path(model)
    assert check_output_path(model / "samples.npz", [model]) == model / "samples.npz"  # a new file beside is fine


def test_models_of_one_kind_in_folders_of_one_name_get_their_own_columns():
    from manifoldgen.bench.sampling import _label
    cvae = CVAE()
    models = {"runs/a/cvae": cvae, "runs/b/cvae": cvae, "runs/c/other": cvae}
    labels = [_label(m, k, models) for k, m in models.items()]
    assert labels == ["cvae (runs/a/cvae)", "cvae (runs/b/cvae)", "cvae (other)"]


# ---------------------------------------------------------------------------------------- training checkpoint
@pytest.fixture(scope="module")
def tiny(panda_task):
    return collect(panda_task, 30, seed=1, conditions=[[0.3], [0.5]], progress=False)


@pytest.fixture(scope="module")
def whole(tiny, tmp_path_factory):
    """The uninterrupted run's model directory."""
    out = tmp_path_factory.mktemp("whole")
    CVAE(**TINY).fit(tiny, epochs=3, seed=0, progress=False, out=out)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("target, call", [("checkpoint.safetensors", 2), ("model.json", 1),
                                          ("training.json", 1)])
def test_a_crash_at_any_write_of_training_resumes_to_the_same_model(tiny, whole, tmp_path, monkeypatch, target,
                                                                    call):
    """The checkpoint is one file replaced by one rename: a crash just before the ``call``-th rename onto
    ``target`` (the temporary file written, the rename not done) leaves a resumable run."""
    original, seen = os.replace, {"n": 0}

    def crash(src, dst):
        if Path(dst).name == target:
            seen["n"] += 1
            if seen["n"] == call:
                raise KeyboardInterrupt
        return original(src, dst)
    monkeypatch.setattr(manifoldgen.io.os, "replace", crash)
    with pytest.raises((KeyboardInterrupt, ManifoldgenError)):
        CVAE(**TINY).fit(tiny, epochs=3, seed=0, progress=False, out=tmp_path / "cut")
    monkeypatch.undo()
    assert (tmp_path / "cut" / "checkpoint.safetensors").is_file()
    CVAE(**TINY).fit(tiny, epochs=3, seed=0, progress=False, out=tmp_path / "cut", resume=True)
    for name in ("model.json", "model.safetensors"):
        assert (tmp_path / "cut" / name).read_bytes() == (whole / name).read_bytes()
    assert not (tmp_path / "cut" / "checkpoint.safetensors").exists()


def test_a_damaged_checkpoint_is_one_clear_error(tiny, tmp_path, monkeypatch):
    import manifoldgen.training as training
    _interrupt_at(monkeypatch, training, "_save_checkpoint", 2)
    with pytest.raises(ManifoldgenError, match="--resume"):
        CVAE(**TINY).fit(tiny, epochs=3, seed=0, progress=False, out=tmp_path)
    blob = (tmp_path / "checkpoint.safetensors").read_bytes()
    for damaged in (blob[:len(blob) // 2], b"\x00" * 8, b"", blob[:8] + b"[" + blob[9:]):
        (tmp_path / "checkpoint.safetensors").write_bytes(damaged)
        with pytest.raises(ManifoldgenError, match="is damaged"):
            CVAE(**TINY).fit(tiny, epochs=3, seed=0, progress=False, out=tmp_path, resume=True)


# ---------------------------------------------------------------------------------------- collision cache
def test_a_mutated_collision_cache_is_recomputed(panda_task, monkeypatch, private_cache):
    robot = panda_task.robot
    monkeypatch.setattr(collision, "MATRIX_SAMPLES", 30)
    candidates = [(a, b) for a in range(8) for b in range(a + 1, 12)]
    fresh = collision._sampled_matrix(robot, candidates)
    (path,) = [p for p in (collision.cache_dir() / "collision").glob("panda-*.json")
               if json.loads(p.read_text()).get("samples") == 30]
    good = json.loads(path.read_text())
    resigned = dict(good, pairs=good["pairs"] + [[0, 99]])
    resigned["pairs_sha256"] = collision._digest(resigned["pairs"])
    mutations = {"truncated": path.read_text()[:40], "binary": "\udcff\x00",
                 "dropped pair": json.dumps(dict(good, pairs=good["pairs"][:-1])),
                 "foreign pair": json.dumps(resigned),
                 "other robot": json.dumps(dict(good, robot_sha256="0" * 64)),
                 "not an object": "[]", "wrong type": json.dumps(dict(good, pairs=[["a", "b"]]))}
    assert good["pairs"] and collision._sampled_matrix(robot, candidates) == fresh  # the cache is used
    for name, text in mutations.items():
        path.write_bytes(text.encode("utf-8", "surrogateescape"))
        with pytest.warns(UserWarning, match="recomputing"):
            assert collision._sampled_matrix(robot, candidates) == fresh, name
        assert json.loads(path.read_text()) == good, name


# ---------------------------------------------------------------------------------------- bench workers
def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_benchmark_workers_die_with_their_parent(tmp_path):
    script = tmp_path / "parent.py"
    script.write_text(textwrap.dedent("""
        import os, time
        from manifoldgen.bench.planning import worker_pool
        if __name__ == "__main__":
            pool = worker_pool(2)
            [f.result() for f in [pool.submit(os.getpid) for _ in range(4)]]
            busy = [pool.submit(time.sleep, 120) for _ in range(2)]  # a running job never reads the pipe
            time.sleep(0.5)
            print(" ".join(str(p) for p in pool._processes), flush=True)
            time.sleep(120)
    """))
    env = {**os.environ, "PYTHONPATH": SRC}
    parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True, env=env)
    try:
        workers = [int(p) for p in parent.stdout.readline().split()]
        assert len(workers) == 2 and all(_alive(p) for p in workers)
        parent.send_signal(signal.SIGKILL)
        parent.wait(10)
        deadline = time.monotonic() + 15
        while any(_alive(p) for p in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_alive(p) for p in workers), "a worker outlived its killed parent"
    finally:
        parent.kill()
        parent.wait()


@pytest.mark.slow
@pytest.mark.parametrize("field, value, problem", [("accuracy", 5.0, "accuracy is 5.0, not a share from 0 to 1"),
                                                   ("recall", "high", "recall is 'high'"),
                                                   ("seed", None, "its model or seed is missing")])
def test_a_tampered_sweep_file_is_refused_on_resume(tmp_path, field, value, problem):
    """A sweep's scores rank its candidates: a resume reads them back whole and refuses a row that is not what a
    sweep writes, naming the row and the field."""
    from manifoldgen.model_sweep import SWEEP_FILE, sweep
    from manifoldgen.tasks import get_task
    dataset = collect(get_task("sphere"), 60, 0, batch=64, progress=False)
    args = dict(models=["cvae"], latents=[2], seeds=[0], epochs=1, progress=False)
    rows = sweep(dataset, tmp_path / "s", **args)
    path = tmp_path / "s" / SWEEP_FILE
    table = json.loads(path.read_text())
    table["candidates"][0][field] = value
    path.write_text(json.dumps(table))
    with pytest.raises(ManifoldgenError, match=f"is damaged \\({rows[0]['name']}: {problem}"):
        sweep(dataset, tmp_path / "s", **args)


@pytest.mark.slow
def test_a_sweep_never_replaces_a_model_it_did_not_make_and_names_other_settings(tmp_path):
    """A sweep into a folder holding a model trained alone is refused before anything is written; a rerun with
    other settings names the first differences."""
    from manifoldgen.model_sweep import sweep
    from manifoldgen.models import CVAE
    from manifoldgen.tasks import get_task
    dataset = collect(get_task("sphere"), 60, 0, batch=64, progress=False)
    CVAE(hidden=[8], batch=8, epochs=1).fit(dataset, seed=0, progress=False, out=tmp_path / "alone")
    before = {p.name: p.read_bytes() for p in (tmp_path / "alone").iterdir()}
    args = dict(models=["cvae"], latents=[2], seeds=[0], epochs=1, progress=False)
    with pytest.raises(ManifoldgenError, match="holds a model that no sweep made .no sweep.json.; choose another"):
        sweep(dataset, tmp_path / "alone", **args)
    assert {p.name: p.read_bytes() for p in (tmp_path / "alone").iterdir()} == before
    sweep(dataset, tmp_path / "s", **args)
    with pytest.raises(ManifoldgenError, match=r"made with other settings \(epochs: 1 then, 2 now\)"):
        sweep(dataset, tmp_path / "s", **{**args, "epochs": 2})
