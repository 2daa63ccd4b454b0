"""Collection on a Ray cluster against collection here (centauro balance, the default shard of 2,048 seeds), and an
estimate of the paper's Table IV at full size on nodes of 16 cores.

    python benchmarks/bench_cluster.py [--per-condition 200] [--conditions 4]

Starts a Ray on this machine with 2 CPUs and prints:

1. the Ray overhead per task: the same batches drawn here and on Ray one task at a time (one worker; the file is
   the same bytes), wall and CPU (target: at most 5 % of a shard's time);
2. collect throughput with 2 workers against 1 (target: at least 1.8x on 2 cores), with CPU beside wall and the
   machine's load (other processes' CPU share over the run: this machine is shared);
3. the paper's Table IV at full size (100 runs x 5 planners x 4 samplers x 2 robots, 30 s limit) on N nodes of 16
   cores: the CPU of a run of each planner and sampler from this repository's PR2 measurements (docs/benchmarks.md,
   Dual-arm tray), an unsolved run charged its full 30 s, plus the CPU per task measured in 1.
"""

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

import manifoldgen.cluster as cluster_module
from manifoldgen.cluster import Cluster
from manifoldgen.data import collect
from manifoldgen.scene import task_checker
from manifoldgen.tasks import get_task

TICK = os.sysconf("SC_CLK_TCK")
# PR2 tray-over, 30 s limit (docs/benchmarks.md, "Table IV, reproduced"): per planner, for the samplers CVAE-6,
# CVAE, CGAN, PG: (success share, mean CPU seconds of a run)
TABLE4 = {"RRT": [(1.0, 0.65), (1.0, 1.85), (0.0, 6.50), (0.8, 4.35)],
          "RRT-Connect": [(1.0, 0.82), (1.0, 1.31), (0.0, 7.76), (1.0, 3.96)],
          "KPIECE": [(1.0, 1.52), (1.0, 1.92), (0.0, 7.39), (0.5, 6.98)],
          "SBL": [(1.0, 2.26), (0.9, 3.47), (0.0, 7.71), (0.1, 9.13)],
          "PRM": [(1.0, 1.04), (1.0, 1.17), (0.0, 7.43), (0.8, 5.97)]}
TABLE4_RUNS, TABLE4_ROBOTS, TABLE4_LIMIT, CORES = 100, 2, 30.0, 16


def ray_cpu() -> dict[str, float]:
    """CPU seconds so far of this machine's Ray processes by pid (workers ``ray::...``, raylet, GCS, agents)."""
    found = {}
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            command = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
            fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
        except OSError:
            continue
        if command[0].startswith(b"ray::") or any(b"/ray/" in part for part in command[:2]):
            found[("worker " if command[0].startswith(b"ray::") else "") + pid] = \
                (int(fields[11]) + int(fields[12])) / TICK  # utime + stime
    return found


def machine_busy() -> tuple[float, float]:
    """(busy, total) CPU seconds of the whole machine so far."""
    values = [int(v) for v in Path("/proc/stat").read_text().splitlines()[0].split()[1:]]
    idle = values[3] + values[4]
    return (sum(values) - idle) / TICK, sum(values) / TICK


def measure(run) -> dict:
    """Wall, this process's CPU, Ray's CPU and the machine's busy share while ``run()`` ran; its result."""
    busy, total = machine_busy()
    wall, cpu, before = time.perf_counter(), time.process_time(), ray_cpu()
    result = run()
    wall, cpu, after = time.perf_counter() - wall, time.process_time() - cpu, ray_cpu()
    busy2, total2 = machine_busy()
    spent = {pid: seconds - before.get(pid, 0.0) for pid, seconds in after.items()}
    ray = sum(spent.values())
    workers = [v for k, v in spent.items() if k.startswith("worker")]
    machine = (busy2 - busy) / (total2 - total)
    return {"result": result, "wall": wall, "cpu": cpu, "ray": ray, "workers": sum(workers),
            "busiest": max(workers, default=0.0),
            "others": max(0.0, machine - (cpu + ray) / (total2 - total)), "machine": machine}


def counting_tasks() -> list:
    """Count the tasks submitted from here on (a surplus batch drawn ahead is a task too)."""
    submitted, submit = [], cluster_module.Pool.submit

    def counted(self, key, fn, *args, **kwargs):
        submitted.append(key)
        return submit(self, key, fn, *args, **kwargs)

    cluster_module.Pool.submit = counted
    return submitted


def warm_up(task) -> None:
    """One small task on each of the 2 workers at once: each rebuilds the task (loads the robot) before timing."""
    from manifoldgen.data import _remote_batch

    with cluster_module.connect(Cluster()) as pool:
        spec = pool.put(json.dumps(task.spec(), sort_keys=True))
        for b in range(2):
            pool.submit(b, _remote_batch, spec, task.condition.grid[0], 0, b, 0, 64, 0.0, None)
        while pool.pending:
            pool.wait()


def round_trips(count: int) -> None:
    """``count`` tasks that do nothing (``len``), two at a time per CPU: the cost of a task itself."""
    with cluster_module.connect(Cluster()) as pool:
        for _ in pool.map_unordered(len, [((),)] * count):
            pass


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--per-condition", type=int, default=200, help="rows per condition value")
    parser.add_argument("--conditions", type=int, default=4, help="condition values of the task's grid")
    args = parser.parse_args()
    import ray

    task = get_task("balance", "centauro")
    task_checker(task)  # warm: the collision matrix is computed once and cached
    values = task.condition.grid[:args.conditions]
    print(f"centauro balance, {args.per_condition} rows at each of {len(values)} condition values, batches "
          f"(shards) of 2,048 seeds; load average before: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    folder = Path(tempfile.mkdtemp(prefix="bench-cluster-"))

    def run(name: str, cluster: Cluster | None):
        return lambda: collect(task, args.per_condition, 0, folder / f"{name}.npz", conditions=values,
                               progress=False, cluster=cluster)

    local = measure(run("local", None))
    started = time.perf_counter()
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    start_s = time.perf_counter() - started
    warm = measure(lambda: warm_up(task))
    trivial = measure(lambda: round_trips(200))
    tasks = counting_tasks()
    one = measure(run("one", Cluster(workers=1)))
    one_tasks = len(tasks)
    two = measure(run("two", Cluster()))
    two_tasks = len(tasks) - one_tasks
    ray.shutdown()
    same = all((folder / f"{n}.npz").read_bytes() == (folder / "local.npz").read_bytes() for n in ("one", "two"))
    rows = len(local["result"])

    def line(name: str, m: dict, shards: int) -> str:
        return (f"  {name:<22} {m['wall']:7.1f} s wall  {m['cpu']:6.1f} s CPU here  {m['workers']:6.1f} s CPU in Ray "
                f"workers  {m['ray'] - m['workers']:4.1f} s in Ray's daemons  "
                f"{rows / m['wall']:6.1f} rows/s  {shards:3d} shards  machine busy {m['machine']:.0%}, "
                f"others {m['others']:.0%}")

    shards = one_tasks  # one task at a time draws exactly the batches a local run draws
    print(f"Ray start {start_s:.1f} s; first task on each worker (the task rebuilt there) {warm['wall']:.1f} s wall")
    print(line("here (1 process)", local, shards))
    print(line("Ray, 1 worker", one, one_tasks))
    print(line("Ray, 2 workers", two, two_tasks))
    per_shard = local["wall"] / shards
    overhead = (one["wall"] - local["wall"]) / shards
    cpu_overhead = (one["cpu"] + one["workers"] - local["cpu"]) / shards
    empty = (trivial["cpu"] + trivial["ray"]) / 200
    print(f"   an empty task costs {trivial['wall'] / 200 * 1e3:.1f} ms wall, {empty * 1e3:.1f} ms CPU (driver and Ray, "
          "200 tasks on 2 workers)")
    print(f"1. overhead per task at 2,048 seeds: {overhead * 1e3:+.0f} ms wall ({overhead / per_shard:+.1%} of a "
          f"shard's {per_shard:.2f} s; target <= 5 %), {cpu_overhead * 1e3:+.0f} ms CPU "
          f"({cpu_overhead / (local['cpu'] / shards):+.1%}: driver and worker); Ray's daemons "
          f"{(one['ray'] - one['workers']) / one['wall']:.1%} of a core while it ran")
    print(f"2. throughput 2 workers / 1 worker: {one['wall'] / two['wall']:.2f}x wall (target >= 1.8x); CPU per row "
          f"{(two['cpu'] + two['workers']) / (one['cpu'] + one['workers']):.2f}x of 1 worker's "
          f"({two_tasks - one_tasks} surplus shards drawn ahead); files byte-identical to the local one: {same}")
    print(f"   CPU of the busiest worker: 1 worker {one['busiest']:.1f} s, 2 workers {two['busiest']:.1f} s: "
          f"{one['busiest'] / max(two['busiest'], 1e-9):.2f}x, the speed-up on 2 cores no other job uses")

    cost = {planner: [p * cpu + (1 - p) * TABLE4_LIMIT for p, cpu in samplers] for planner, samplers in
            TABLE4.items()}
    per_run = float(np.mean([c for costs in cost.values() for c in costs]))
    runs = TABLE4_RUNS * TABLE4_ROBOTS * sum(len(c) for c in cost.values())
    total = runs * (per_run + max(0.0, cpu_overhead))
    print(f"3. Table IV at full size: {runs:,} runs, mean {per_run:.1f} CPU s each (unsolved: {TABLE4_LIMIT:.0f} s), "
          f"{total / 3600:.1f} CPU hours with the Ray overhead; on this machine's 2 cores {total / 2 / 3600:.1f} h")
    for nodes in (1, 2, 4, 8, 16):
        wall = total / (nodes * CORES) + TABLE4_LIMIT  # the last run can start as the others end
        print(f"   {nodes:2d} node(s) of {CORES} cores: {wall / 60:6.1f} min")


if __name__ == "__main__":
    main()
