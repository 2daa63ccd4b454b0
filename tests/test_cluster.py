"""Collect, bench and sweep on a real Ray cluster (a head and a second node, one CPU each): the same bytes and
records as a local run, whatever the finish order; a worker killed mid-task, a driver killed mid-run and a node
that leaves lose and duplicate nothing; bad clusters fail in one line."""

import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from manifoldgen.bench.planning import Experiment, read_records, run_bench
from manifoldgen.cluster import Cluster, connect, parse_cluster
from manifoldgen.data import collect
from manifoldgen.errors import ManifoldgenError
from manifoldgen.tasks import get_task

ray = pytest.importorskip("ray", reason="the [ray] extra is not installed: pip install 'manifoldgen[ray]'")
from ray.cluster_utils import Cluster as RayCluster  # noqa: E402

SPHERE = dict(per_condition=120, seed=4, batch=32)  # 5 condition values, several batches each
BENCH_METHODS = ["project=rrtconnect@project"]
TIMINGS = {"time_s", "cpu_s", "build_s", "harness_cpu_s", "host", "node"}


@pytest.fixture(scope="module")
def cluster():
    """A head node and a worker node (one CPU each) on this machine, joined by this process; stopped at the end."""
    fast_death = {"health_check_initial_delay_ms": 0, "health_check_period_ms": 200,  # a node that leaves is
                  "health_check_failure_threshold": 2}  # declared dead within a second, not Ray's default 30 s
    nodes = RayCluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False,
                                                             "_system_config": fast_death})
    worker = nodes.add_node(num_cpus=1)
    ray.init(address=nodes.address, log_to_driver=False, logging_level="ERROR")
    nodes.wait_for_nodes()
    yield nodes, worker
    ray.shutdown()
    nodes.shutdown()


@pytest.fixture(scope="module")
def sphere():
    return get_task("sphere")


def _without_timings(record: dict) -> dict:
    """A bench record without its timings (and the words that print one) and node names."""
    extras = {k: v for k, v in record.get("extras", {}).items() if not k.endswith("_s")}
    why = re.sub(r"in [0-9.]+ s", "in T s", record.get("why", ""))
    return {k: v for k, v in record.items() if k not in TIMINGS} | {"extras": extras, "why": why}


def test_parse_cluster_names_one_meaning():
    assert parse_cluster(None) is None and parse_cluster("ray") == Cluster(None, None)
    assert parse_cluster("ray:10.0.0.5:6379", 3) == Cluster("10.0.0.5:6379", 3)
    for bad, message in [("dask", "--cluster takes ray"), ("ray:", "--cluster takes ray"),
                         ("ray:ray://head:10001", "Ray Client addresses are not supported")]:
        with pytest.raises(ManifoldgenError, match=message):
            parse_cluster(bad)
    with pytest.raises(ManifoldgenError, match="tasks running at once"):
        parse_cluster("ray", 0)


def test_without_cluster_nothing_imports_ray_and_without_the_extra_one_line_names_it(tmp_path):
    code = ("import sys\nfrom manifoldgen.cli import app\n"
            "for args in (['collect', '--help'], ['bench', 'plan', '--help'], ['sweep', '--help']):\n"
            "    try:\n        app(args)\n    except SystemExit:\n        pass\n"
            "print(sorted({'ray', 'torch'} & set(sys.modules)))\n"
            "sys.modules['ray'] = None  # as if the extra were not installed\n"
            f"app(['collect', 'sphere', '--per-condition', '5', '--cluster', 'ray', '-o', '{tmp_path / 'x.npz'}'])")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    lines = done.stdout.strip().splitlines()
    assert "--cluster" in done.stdout and lines[-1] == "[]", done.stdout + done.stderr
    assert done.returncode == 2 and done.stderr.strip() == "error: --cluster ray needs the [ray] extra: pip install " \
        "'manifoldgen[ray]'"


@pytest.mark.slow
def test_collect_on_the_cluster_writes_the_local_bytes(cluster, sphere, tmp_path):
    local = tmp_path / "local.npz"
    collect(sphere, out=local, progress=False, **SPHERE)
    for name, workers in (("deep", None), ("one", 1)):  # a queue two deep per CPU, and one task at a time
        out = tmp_path / f"{name}.npz"
        collect(sphere, out=out, progress=False, cluster=Cluster(workers=workers), **SPHERE)
        assert out.read_bytes() == local.read_bytes()
        assert not out.with_name(out.name + ".partial").exists()


@pytest.mark.slow
def test_bench_on_the_cluster_records_what_a_local_run_does(cluster, tmp_path):
    experiment = Experiment("sphere", "sphere", "point", time_limit=60.0, seed=0)  # runs take 0.1 s of CPU
    run_bench(experiment, BENCH_METHODS, tmp_path / "local", runs=4, progress=False)
    out = tmp_path / "ray"
    run_bench(experiment, BENCH_METHODS, out, runs=2, progress=False, cluster=Cluster())
    run_bench(experiment, BENCH_METHODS, out, runs=4, resume=True, progress=False, cluster=Cluster())
    local, remote = read_records(tmp_path / "local" / "runs.jsonl"), read_records(out / "runs.jsonl")
    key = lambda r: (r["method"], r["run"])  # noqa: E731
    assert sorted(map(key, remote)) == sorted(map(key, local))  # resume ran only the missing runs
    assert all(r["solved"] for r in local)
    assert [_without_timings(r) for r in sorted(remote, key=key)] == \
        [_without_timings(r) for r in sorted(local, key=key)]
    nodes = {r["node"] for r in remote}
    assert len(nodes) == 2 and all(r["cpu_s"] > 0 and r["host"] == socket.gethostname() for r in remote)


def _running_tasks(parent: int | None = None) -> list[int]:
    """Worker processes running a task (their title is ``ray::_call``), of the raylet ``parent`` if given."""
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            title = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[0]
            ppid = int(Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        if title.startswith(b"ray::_call") and parent in (None, ppid):
            found.append(int(pid))
    return found


def _while_collecting(task, out: Path, args: dict, fault) -> None:
    """Collect on the cluster while ``fault()`` runs beside it until it returns True (it must, mid-run)."""
    struck, stop = [], threading.Event()

    def watch():
        while not stop.is_set() and not struck:
            if fault():
                struck.append(True)
            time.sleep(0.002)

    watcher = threading.Thread(target=watch)
    watcher.start()
    try:
        collect(task, out=out, cluster=Cluster(), **args)
    finally:
        stop.set()
        watcher.join()
    assert struck, "the fault never found a task running"


PANDA = dict(per_condition=60, seed=1, batch=256, conditions=np.array([[0.3], [0.5]]), progress=False)


def test_a_worker_killed_mid_task_loses_and_duplicates_no_row(cluster, panda_task, tmp_path):
    collect(panda_task, out=tmp_path / "local.npz", **PANDA)

    def kill_a_worker():
        running = _running_tasks()
        for pid in running[:1]:
            os.kill(pid, signal.SIGKILL)
        return bool(running)

    _while_collecting(panda_task, tmp_path / "ray.npz", PANDA, kill_a_worker)
    assert (tmp_path / "ray.npz").read_bytes() == (tmp_path / "local.npz").read_bytes()


@pytest.mark.slow  # two driver processes start
def test_a_killed_driver_resumes_to_the_same_bytes(cluster, sphere, tmp_path):
    nodes, _ = cluster
    local = tmp_path / "local.npz"
    args = dict(per_condition=300, seed=2, batch=16)
    collect(sphere, out=local, progress=False, **args)
    out = tmp_path / "ray.npz"
    partial = out.with_name(out.name + ".partial")
    driver_code = ("import sys; from manifoldgen.cluster import Cluster; from manifoldgen.data import collect; "
                   "from manifoldgen.tasks import get_task; "
                   f"collect(get_task('sphere'), out=sys.argv[1], progress=False, "
                   f"cluster=Cluster(sys.argv[2]), **{args!r})")
    driver = subprocess.Popen([sys.executable, "-c", driver_code, str(out), nodes.address], stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 60
    while len(list(partial.glob("c*-b*.npz"))) < 5 and driver.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    driver.kill()  # SIGKILL: no clean-up runs
    driver.wait()
    assert not out.exists() and len(list(partial.glob("c*-b*.npz"))) >= 5
    done = subprocess.run([sys.executable, "-c", driver_code, str(out), nodes.address], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert out.read_bytes() == local.read_bytes()


def test_a_worker_with_another_manifoldgen_is_refused_in_one_line(cluster, monkeypatch):
    with connect(Cluster()) as pool:
        pool.version = "0.0.0"  # what a driver of another version would expect
        with pytest.raises(ManifoldgenError, match=r"runs manifoldgen .*, the driver 0\.0\.0: install the same") as exc:
            list(pool.map_unordered(len, [("ab",)]))
    assert "\n" not in str(exc.value)
    import manifoldgen.cluster as cluster_module
    monkeypatch.setattr(cluster_module, "DISTRIBUTION", "manifoldgen-not-installed")
    monkeypatch.setattr(cluster_module, "_version", lambda: "0.1.0")
    with pytest.raises(ManifoldgenError, match="has no manifoldgen installed: install manifoldgen==0.1.0"):
        with connect(Cluster()):
            pass


def test_a_cluster_nobody_answers_at_fails_in_one_line_and_fast(tmp_path):
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]  # free once closed: nothing listens there
    start = time.monotonic()
    done = subprocess.run([sys.executable, "-c", "from manifoldgen.cli import app; app()", "collect", "sphere",
                           "--per-condition", "10", "--cluster", f"ray:127.0.0.1:{port}", "-o",
                           str(tmp_path / "x.npz")], capture_output=True, text=True, timeout=60)
    assert time.monotonic() - start < 30
    assert done.returncode == 2 and not done.stdout and done.stderr.strip().count("\n") == 0, done.stdout + done.stderr
    assert f"no Ray cluster answers at 127.0.0.1:{port}" in done.stderr
    assert not (tmp_path / "x.npz").exists()


@pytest.mark.slow  # trains models, each worker imports torch
def test_a_sweep_on_the_cluster_ranks_and_writes_what_a_local_sweep_does(cluster, sphere, tmp_path):
    from manifoldgen.model_sweep import SWEEP_FILE, sweep
    from manifoldgen.selection import RECALL_SLACK
    dataset = collect(sphere, 60, 0, batch=64, progress=False)
    args = dict(models=["cvae", "cfm"], latents=[2, 3], seeds=[0], epochs=2, progress=False)
    local = sweep(dataset, tmp_path / "local", **args)
    remote = sweep(dataset, tmp_path / "ray", cluster=Cluster(), **args)
    strip = lambda rows: [{k: v for k, v in r.items() if k not in TIMINGS | {"seconds"}} for r in rows]  # noqa: E731
    assert strip(remote) == strip(local)
    assert sorted(r["name"] for r in local) == ["cfm-seed0", "cvae-latent2-seed0", "cvae-latent3-seed0"]  # no latent
    assert local[0]["chosen"] and [r["rank"] for r in local] == [1, 2, 3]
    best = max(r["recall"] for r in local)
    near = [r for r in local if r["recall"] >= best - RECALL_SLACK]
    assert local[:len(near)] == sorted(near, key=lambda r: -r["accuracy"])
    for file in ("model.safetensors", "model.json"):
        assert (tmp_path / "ray" / file).read_bytes() == (tmp_path / "local" / file).read_bytes() == \
            (tmp_path / "local" / "candidates" / local[0]["name"] / file).read_bytes()
    table = json.loads((tmp_path / "ray" / SWEEP_FILE).read_text())
    assert [r["name"] for r in table["candidates"]] == [r["name"] for r in local]
    assert {r["node"] for r in table["candidates"]} <= {n["NodeID"] for n in ray.nodes()}
    assert sweep(dataset, tmp_path / "ray", **args) == remote  # a rerun trains nothing: every candidate is kept
    with pytest.raises(ManifoldgenError, match="other settings"):
        sweep(dataset, tmp_path / "ray", **{**args, "epochs": 3})


def test_a_node_that_leaves_mid_run_loses_and_duplicates_no_row(cluster, panda_task, tmp_path):
    """Last in the file: the cluster keeps one node after it."""
    nodes, worker = cluster
    collect(panda_task, out=tmp_path / "local.npz", **PANDA)
    raylet = worker.all_processes["raylet"][0].process.pid

    def remove_the_worker_node():
        if not _running_tasks(raylet):
            return False
        nodes.remove_node(worker, allow_graceful=False)
        return True

    _while_collecting(panda_task, tmp_path / "ray.npz", PANDA, remove_the_worker_node)
    assert (tmp_path / "ray.npz").read_bytes() == (tmp_path / "local.npz").read_bytes()
    assert not _running_tasks(raylet)
