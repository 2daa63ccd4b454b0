"""The learned sampler at its defaults against projection and C++ Atlas, as a new user runs it.

For every (task, scene) given (default: the held-out set in benchmarks/heldout/), through the public CLI
and nothing else: ``collect`` and ``train`` with default settings, one ``plan`` of the scene (the time from
a task file to a first learned path), then ``bench plan`` of the learned sampler, ``project`` (uniform +
projection) and C++ OMPL Atlas on the same seeds. Prints one table: rows per method with solved runs, median
CPU and wall time of the solved runs, and median path length; and the pipeline's wall and CPU time. Where the C++
baseline cannot take the task (a user constraint whose residual does not trace), OMPL's Atlas runs through Python
callbacks (``atlas-python``).

    python benchmarks/bench_defaults.py -o runs/defaults                      # the held-out set, 30 seeds
    python benchmarks/bench_defaults.py -o runs/shipped pose-panda.toml@maze dualarm-pr2.toml@tray-over ...

An entry is ``TASK@SCENE``: a task file (or a built-in task file's name under src/manifoldgen/tasks/).
Work is kept per entry in the output folder; a rerun reuses the collected data, the model and finished runs.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
import tomllib
from pathlib import Path

from manifoldgen.bench.planning import read_records
from manifoldgen.models import open_model

ROOT = Path(__file__).resolve().parents[1]
HELDOUT = ["dualarm-tiago.toml@tray-over", "balance-g1.toml@reach", "sphere-ur5.toml@shelves",
           "pose-kinova.toml@pillars"]
ATLAS = ("atlas-c++=ompl-native-atlas", "atlas-python=ompl-atlas-rrtconnect")
CLI = [sys.executable, "-c", "from manifoldgen.cli import app; app()"]


def task_path(name: str) -> Path:
    for folder in (Path.cwd(), ROOT / "benchmarks" / "heldout", ROOT / "src" / "manifoldgen" / "tasks"):
        if (folder / name).is_file():
            return folder / name
    raise SystemExit(f"no task file {name} here, in benchmarks/heldout/ or in src/manifoldgen/tasks/")


def timed(args: list[str], log: Path) -> tuple[float, float, int]:
    """Run ``manifoldgen ARGS`` (output appended to ``log``); its wall and CPU seconds and exit code."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    with log.open("a") as out:
        out.write(f"$ manifoldgen {' '.join(args)}\n")
        out.flush()
        code = subprocess.call(CLI + args, stdout=out, stderr=subprocess.STDOUT)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return time.perf_counter() - start, cpu, code


def median(values: list[float]) -> float:
    return statistics.median(values) if values else float("nan")


def run_entry(entry: str, out: Path, runs: int, seed: int, time_limit: float) -> list[dict]:
    """Pipeline and benchmark of one ``TASK@SCENE``; one summary row per method."""
    name, _, scene = entry.partition("@")
    task = task_path(name)
    if scene not in tomllib.loads(task.read_text()).get("scenes", {}):
        raise SystemExit(f"{entry}: task file {task.name} names no scene '{scene}'")
    folder = out / f"{task.stem}-{scene}"
    folder.mkdir(parents=True, exist_ok=True)
    log = folder / "log.txt"
    data, model = folder / "data.npz", folder / "model"
    pipeline = {"collect": (0.0, 0.0), "train": (0.0, 0.0), "plan": (0.0, 0.0)}
    if not data.exists():
        wall, cpu, code = timed(["collect", str(task), "-o", str(data)], log)
        pipeline["collect"] = (wall, cpu)
        if code:
            raise SystemExit(f"collect failed for {entry}; see {log}")
    if not (model / "model.json").exists():
        wall, cpu, code = timed(["train", str(data), "--task", str(task), "-o", str(model)], log)
        pipeline["train"] = (wall, cpu)
        if code:
            raise SystemExit(f"train failed for {entry}; see {log}")
    saved = open_model(model)
    kind = "projection only" if saved.mix == 1 else saved.label  # 1: train's race chose plain projection
    sampler = f"model:{model}"
    wall, cpu, _ = timed(["plan", str(task), "--scene", scene, "--sampler", sampler, "--seed", str(seed),
                          "-o", str(folder / "first-path.npz")], log)
    pipeline["plan"] = (wall, cpu)
    bench = folder / "bench"
    for atlas in ATLAS:  # C++ Atlas, or OMPL's Atlas through Python where the C++ baseline cannot take the task
        *_, code = timed(["bench", "plan", str(task), "--scene", scene, "--runs", str(runs), "--seed", str(seed),
                          "--time", str(time_limit), "-m", f"learned=rrtconnect@{sampler}", "-m",
                          "project=rrtconnect@project", "-m", atlas, "-o", str(bench),
                          *(["--resume"] if (bench / "runs.jsonl").exists() else [])], log)
        if code == 0:
            break
    else:
        raise SystemExit(f"bench plan failed for {entry}; see {log}")
    records = read_records(bench / "runs.jsonl")
    rows = []
    for method in ("learned", "project", atlas.partition("=")[0]):
        mine = [r for r in records if r["method"] == method]
        solved = [r for r in mine if r["solved"] and r.get("valid", True)]
        rows.append({"entry": entry, "method": method, "model": kind if method == "learned" else "",
                     "solved": len(solved), "runs": len(mine), "cpu_ms": 1000 * median([r["cpu_s"] for r in solved]),
                     "wall_ms": 1000 * median([r["time_s"] for r in solved]),
                     "length": median([r["length"] for r in solved])})
    rows[0]["pipeline"] = {k: {"wall_s": round(w, 1), "cpu_s": round(c, 1)} for k, (w, c) in pipeline.items()}
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("entries", nargs="*", default=HELDOUT, help="TASK@SCENE (default: the held-out set)")
    parser.add_argument("-o", "--output", type=Path, required=True)
    parser.add_argument("--runs", type=int, default=30)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--time", type=float, default=30.0)
    args = parser.parse_args()
    rows = [row for entry in args.entries for row in run_entry(entry, args.output, args.runs, args.seed, args.time)]
    (args.output / "summary.json").write_text(json.dumps(rows, indent=1))
    print("| task @ scene | method | solved | median CPU (ms) | median wall (ms) | path length (rad) |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        label = f"learned ({r['model']})" if r["model"] else r["method"]
        print(f"| {r['entry']} | {label} | {r['solved']}/{r['runs']} | {r['cpu_ms']:.1f} | {r['wall_ms']:.1f} | "
              f"{r['length']:.2f} |")
    print("\npipeline, task file -> first learned path (a rerun reuses data and model: 0 s):")
    for r in rows:
        if "pipeline" in r:
            p = r["pipeline"]
            wall, cpu = sum(v["wall_s"] for v in p.values()), sum(v["cpu_s"] for v in p.values())
            print(f"  {r['entry']}: {wall:.0f} s wall, {cpu:.0f} s CPU (" +
                  ", ".join(f"{k} {v['wall_s']:.0f}/{v['cpu_s']:.0f}" for k, v in p.items()) + " s wall/CPU)")


if __name__ == "__main__":
    main()
