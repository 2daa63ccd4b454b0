"""Our learned sampler against OMPL at native speed: panda wall and maze, same queries and seeds.

    python benchmarks/bench_ompl_native.py [--runs 30] [--seed 0] [--time 10] [--scenes wall maze]
                                           [--methods cvae atlas-c++ ...] [--workers 1]
                                           [--out runs/ompl-native] [--resume] [--set KEY=VALUE ...]

Methods, interleaved per seed in one run: the shipped CVAE with RRT-Connect (our default local
planner; its search runs in the compiled core when ``manifoldgen_core`` is built, see
:mod:`manifoldgen.native`) and the C++ OMPL baseline (``ompl-native-atlas``, ``-projected``, ``-tangent``: RRTConnect
with our constraint and collision checker compiled; build it first with
``benchmarks/ompl_native/build.sh``). Every path gets the same dense check (0.005 rad) and the same
retry policy. Prints per scene and method: success, median CPU and wall time (an unsolved run
counts as slower than every solved one; CPU includes the dense check of the returned paths; the C++
baseline's is its program's plus that check, not the harness that starts it and passes paths), and the median coal collision checks, sphere tests (ours with
``--set spheres=true``), FK evaluations, samples drawn (ours: rows decoded by the CVAE; OMPL's: by its
own sampler) and, ours, samples used (refined and checked when the search first used them, valid), and the
path length (joint-space, rad) of the solved runs, with spheres also the certified sweep tests of the dense checks and the collision queries (sphere
tests + sweep tests); each
scene's full report (``results.md``, every run in ``runs.jsonl``) is in OUT/SCENE.
"""

import argparse
from dataclasses import fields
from pathlib import Path

import numpy as np

from manifoldgen.bench.planning import RUNS_FILE, Experiment, read_records, run_bench
from manifoldgen.models import pretrained_model_dir
from manifoldgen.planning.rrt_connect import RRTConnectSettings
from manifoldgen.runtime import set_threads
from manifoldgen.settings import parse_settings

METHODS = ["cvae=rrtconnect@cvae:{model}", "atlas-c++=ompl-native-atlas", "projected-c++=ompl-native-projected",
           "tangent-c++=ompl-native-tangent"]


def _median(values: list[float], failures: int) -> str:
    """Median with ``failures`` runs counted as slower than every value ('> limit' when they hold it)."""
    ranked = sorted(values) + [np.inf] * failures
    value = float(np.median(ranked)) if ranked else np.inf
    return "> limit" if not np.isfinite(value) else f"{value:.3g}"


def summary(records: list[dict], methods: list[str], scene: str) -> list[str]:
    rows = []
    for method in methods:
        runs = [r for r in records if r["method"] == method]
        solved = [r for r in runs if r["solved"]]
        failed = len(runs) - len(solved)
        ops = {k: (f"{np.median([r['ops'][k] for r in solved]):,.0f}" if solved else "-")
               for k in ("collision_checks", "fk", "samples")}
        spheres = [r["extras"].get("sphere_checks", 0) for r in solved]
        sweeps = [r["extras"].get("sweep_checks", 0) for r in solved]
        queries = [a + b for a, b in zip(spheres, sweeps)]
        used = [r["extras"]["sampler"]["accepted"] for r in solved if "sampler" in r.get("extras", {})]
        length = f"{np.median([r['length'] for r in solved]):.2f}" if solved else "-"
        native = [r["extras"]["native_cpu_s"] for r in solved if "native_cpu_s" in r.get("extras", {})]
        rows.append(f"| {scene} | {method} | {len(solved)}/{len(runs)} | "
                    f"{_median([r['cpu_s'] for r in solved], failed)} | "
                    f"{f'{np.median(native):.3g}' if native else '-'} | "
                    f"{_median([r['time_s'] for r in solved], failed)} | {ops['collision_checks']} | "
                    f"{f'{np.median(spheres):,.0f}' if any(spheres) else '-'} | "
                    f"{f'{np.median(sweeps):,.0f}' if any(sweeps) else '-'} | "
                    f"{f'{np.median(queries):,.0f}' if any(sweeps) else '-'} | {ops['fk']} | {ops['samples']} | "
                    f"{f'{np.median(used):,.0f}' if used else '-'} | "
                    f"{length} |")
    return rows


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=30)
    parser.add_argument("--seed", type=int, default=0, help="first seed (run r uses seed + r): another seed set "
                        "to choose settings on, apart from the table's seeds 0..runs-1")
    parser.add_argument("--time", type=float, default=10.0)
    parser.add_argument("--scenes", nargs="*", default=["wall", "maze"])
    parser.add_argument("--methods", nargs="*", default=None, help="labels to run (default: all): "
                        + ", ".join(m.split("=")[0] for m in METHODS))
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--out", default="runs/ompl-native")
    parser.add_argument("--resume", action="store_true")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a setting of our planners (e.g. spheres=true, which the C++ OMPL methods take too: "
                        "the same collision checks); the other OMPL settings stay OMPL's")
    args = parser.parse_args()
    set_threads()  # as every command: torch's and numpy's BLAS threads sized for this machine
    settings = parse_settings(args.set, None, {f.name: f.default for f in fields(RRTConnectSettings)}, "planner")
    methods = [m.format(model=pretrained_model_dir()) for m in METHODS]
    if args.methods:
        unknown = set(args.methods) - {m.split("=")[0] for m in methods}
        if unknown:
            parser.error(f"unknown methods {sorted(unknown)}; known: {[m.split('=')[0] for m in methods]}")
        methods = [m for m in methods if m.split("=")[0] in args.methods]
    labels = [m.split("=")[0] for m in methods]
    lines = ["| scene | method | solved | median CPU (s) | of which C++ OMPL, solved (s) | median wall (s) "
             "| coal collision checks, solved (median) | sphere tests | sweep tests | collision queries (sphere + sweep "
             "tests) | FK evaluations, solved (median) | samples drawn, solved (median) | samples used (made valid) "
             "| path length, solved (rad, median) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    Path(args.out).mkdir(parents=True, exist_ok=True)
    for scene in args.scenes:
        out = Path(args.out) / scene
        run_bench(Experiment(scene, time_limit=args.time, seed=args.seed, planner_settings=settings), methods, out,
                  runs=args.runs, workers=args.workers, resume=args.resume)
        records = [r for r in read_records(out / RUNS_FILE) if r["run"] < args.runs]
        lines += summary(records, labels, scene)
    print(f"{args.runs} seeds per method (from {args.seed}), {args.time:g} s limit, {args.workers} worker(s), "
          f"methods interleaved per seed; full reports in {args.out}/SCENE/results.md")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
