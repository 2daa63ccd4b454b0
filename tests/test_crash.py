"""Crash tests: ``collect`` and ``train`` are killed with SIGKILL in a subprocess just before or just after
one of their file replacements (the moments a kill could tear a file), and ``bench plan`` after a finished
run, then rerun: the final files equal an uninterrupted run's (bytes; the benchmark's records up to their
timings), and no temporary file or worker process is left."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from manifoldgen.data import collect
from manifoldgen.dataset import Dataset
from manifoldgen.models import CVAE

pytestmark = pytest.mark.slow  # the quick loop (pytest -m "not slow") leaves this module out

SRC = str(Path(__file__).resolve().parents[1] / "src")
COLLECT = {"conditions": [[0.3], [0.5]], "batch": 16, "progress": False}
TRAIN = {"hidden": [8], "batch": 8, "patience": 50}

# Runs JOB, killing itself with SIGKILL at the K-th os.replace (before it when K > 0, after it when K < 0).
KILLER = textwrap.dedent("""
    import os, signal, sys
    job, out, k = sys.argv[1], sys.argv[2], int(sys.argv[3])
    replace, seen = os.replace, [0]
    def killing(src, dst):
        seen[0] += 1
        if seen[0] == k:
            os.kill(os.getpid(), signal.SIGKILL)
        replace(src, dst)
        if seen[0] == -k:
            os.kill(os.getpid(), signal.SIGKILL)
    os.replace = killing
    from manifoldgen.data import collect
    from manifoldgen.dataset import Dataset
    from manifoldgen.models import CVAE
    from manifoldgen.tasks import get_task
    if job == "collect":
        collect(get_task("pose", "panda"), 6, 3, out, conditions=[[0.3], [0.5]], batch=16, progress=False)
    else:
        data = Dataset.load(sys.argv[4])
        CVAE(hidden=[8], batch=8, patience=50).fit(data, epochs=3, seed=0, progress=False, out=out)
    print("finished")
""")


def _killed_at(tmp_path: Path, job: str, out: Path, k: int, *extra: str) -> None:
    script = tmp_path / "killer.py"
    script.write_text(KILLER)
    env = {**os.environ, "PYTHONPATH": SRC}
    done = subprocess.run([sys.executable, str(script), job, str(out), str(k), *extra], env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == -9, (done.returncode, done.stderr[-2000:])


@pytest.mark.parametrize("k", [1, -3])  # before the partial stamp; after a batch
def test_collect_killed_then_rerun_gives_the_same_bytes(panda_task, tmp_path, k):
    whole = tmp_path / "whole.npz"
    collect(panda_task, 6, 3, whole, **COLLECT)
    out = tmp_path / "cut" / "d.npz"
    out.parent.mkdir()
    _killed_at(tmp_path, "collect", out, k)
    collect(panda_task, 6, 3, out, **COLLECT)  # the same command again
    assert out.read_bytes() == whole.read_bytes()
    assert sorted(p.name for p in out.parent.iterdir()) == ["d.npz"]  # no partial folder, no temporary file


@pytest.fixture(scope="module")
def dataset_file(tmp_path_factory, panda_task):
    path = tmp_path_factory.mktemp("crash") / "data.npz"
    collect(panda_task, 30, 1, conditions=[[0.3], [0.5]], progress=False).save(path)
    return path


@pytest.mark.parametrize("k", [2, -4])  # before a checkpoint; between the weights and model.json
def test_train_killed_then_resumed_gives_the_same_model(dataset_file, tmp_path, k):
    """Writes: checkpoint after epochs 1-3 (renames 1-3), then model.safetensors (4), model.json (5), ..."""
    data = Dataset.load(dataset_file)
    CVAE(**TRAIN).fit(data, epochs=3, seed=0, progress=False, out=tmp_path / "whole")
    out = tmp_path / "cut"
    _killed_at(tmp_path, "train", out, k, str(dataset_file))
    resume = (out / "checkpoint.safetensors").exists()
    assert resume  # every kill point lies after the first checkpoint
    CVAE(**TRAIN).fit(data, epochs=3, seed=0, progress=False, out=out, resume=resume)
    for name in ("model.json", "model.safetensors"):
        assert (out / name).read_bytes() == (tmp_path / "whole" / name).read_bytes(), name
    assert not [p.name for p in out.iterdir() if p.name.endswith(".tmp") or p.name.startswith("checkpoint")]


TIMED = {"build_s", "cpu_s", "time_s", "why", "late"}  # what a run measured of the machine's speed


def test_bench_killed_then_resumed_gives_the_same_runs(tmp_path):
    """``bench plan`` SIGKILLed after its first finished run, then rerun with --resume: the same records
    (up to their timings) as an uninterrupted benchmark, and its worker gone with it."""
    from manifoldgen.bench.planning import RUNS_FILE, Experiment, read_records, run_bench
    methods, experiment = ["rrtconnect@project"], Experiment("wall", "pose", "panda", 30.0, 0)
    run_bench(experiment, methods, tmp_path / "whole", runs=3, progress=False)
    out = tmp_path / "cut"
    command = [sys.executable, "-c", "from manifoldgen.cli import app; app()", "bench", "plan", "pose", "--scene",
               "wall", "-m", methods[0], "--runs", "3", "--time", "30", "-o", str(out)]
    bench = subprocess.Popen(command, env={**os.environ, "PYTHONPATH": SRC}, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (out / RUNS_FILE).is_file():
            time.sleep(0.02)
        children = [int(p) for p in Path(f"/proc/{bench.pid}/task/{bench.pid}/children").read_text().split()]
        while time.monotonic() < deadline and not read_records(out / RUNS_FILE):
            time.sleep(0.02)
        bench.send_signal(signal.SIGKILL)
        bench.wait(10)
    finally:
        bench.kill()
        bench.wait()
    assert len(read_records(out / RUNS_FILE)) < 3  # killed mid-way
    time.sleep(1)
    assert not [p for p in children if Path(f"/proc/{p}").exists()
                and Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()[0] not in "ZX"]
    run_bench(experiment, methods, out, runs=3, resume=True, progress=False)

    def runs(folder):
        return sorted(({k: v for k, v in r.items() if k not in TIMED} for r in read_records(folder / RUNS_FILE)),
                      key=lambda r: (r["method"], r["run"]))
    assert runs(out) == runs(tmp_path / "whole") and len(runs(out)) == 3
