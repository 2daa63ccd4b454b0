"""OMPL's sphere demo: our planner against the demo itself in C++ (Atlas, Projected, TangentBundle), same seeds.

    python benchmarks/bench_sphere_demo.py [--runs 30] [--seed 0] [--time 10] [--model DIR] [--set KEY=VALUE ...]
                                           [--out runs/sphere-demo] [--ompl-tolerance 1e-4]

The problem is the task ``sphere`` with its scene ``sphere`` (a point on the unit sphere, the demo's
three bands, south pole to north pole). Methods, interleaved per seed (run r uses seed SEED + r):

- ``cvae``: our default planner (``rrtconnect``, its default local planner and settings, or those
  given with ``--set``) with the learned sampler: a CVAE trained on 10,000 rows of the task
  (``OUT/cvae``, collected and trained here once, about a minute, unless ``--model`` names one);
- ``project``: the same planner with uniform samples projected onto the sphere;
- ``atlas-c++``, ``projected-c++``, ``tangent-c++``: ``benchmarks/ompl_native/build/sphere_demo``
  (build it with ``benchmarks/ompl_native/build.sh``): the demo's problem in C++ with the demo's
  settings (OMPL tolerance ``--ompl-tolerance`` on |F|), each exact solution densely checked as ours
  are (every 0.005 m, within the task's tolerance, outside the bands; a refused path: search again).

Prints per method: success, median CPU and wall time (an unsolved run counts as slower than every
solved one), and the medians over solved runs of constraint evaluations (F or J; ours: every
configuration whose constraint kinematics was computed), Jacobians, validity checks (ours: collision
checks with coal, beside the sphere tests that ran first with ``--set spheres=true``; OMPL: its validity
checker's calls plus the dense check's states), samples drawn (ours: raw rows the sampler made), samples
used (ours: rows refined and checked when the search first used them, valid), tree nodes.
Ours: CPU of ``Planner.solve`` (its own final dense check included); C++: CPU from building the
space to the final verdict. Every run is a JSON line in ``OUT/runs.jsonl``; ``--resume`` keeps them.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
from pathlib import Path

import numpy as np

from manifoldgen.bench.planning import Experiment, Method, read_records, run_once
from manifoldgen.errors import ManifoldgenError
from manifoldgen.progress import progress_bar
from manifoldgen.runtime import set_threads
from manifoldgen.settings import parse_settings

HERE = Path(__file__).resolve().parent
PROGRAM = HERE / "ompl_native" / "build" / "sphere_demo"
SPACES = {"atlas-c++": "atlas", "projected-c++": "projected", "tangent-c++": "tangent"}
ROWS = 2000  # per condition value (5 radii): 10,000 rows


def ensure_model(out: Path) -> Path:
    """A CVAE for the task, trained once into ``out / "cvae"`` (seeded: the same model every time)."""
    model = out / "cvae"
    if (model / "model.json").is_file():
        return model
    from manifoldgen.data import collect
    from manifoldgen.models import get_model_class
    from manifoldgen.tasks import get_task

    data = collect(get_task("sphere"), ROWS, 0, out / "data.npz")
    get_model_class("cvae")().fit(data, seed=0, out=model)
    return model


def run_native(space: str, seed: int, args: argparse.Namespace, tolerance: float) -> dict:
    """One seed of the C++ demo program as a record shaped like ours."""
    command = [str(PROGRAM), "--space", space, "--seeds", str(seed), "--time", str(args.time),
               "--tolerance", str(args.ompl_tolerance), "--check-tolerance", str(tolerance)]
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise ManifoldgenError(f"{' '.join(command)} failed: {done.stderr.strip()[-300:]}")
    r = json.loads(done.stdout.strip().splitlines()[-1])
    return {**r, "time_s": r["time_s"], "cpu_s": r["cpu_s"],
            "ops": {"fk": r["function_calls"] + r["jacobian_calls"], "jacobians": r["jacobian_calls"],
                    "collision_checks": r["validity_checks"] + r["dense_checks"], "samples": r["samples"],
                    "nodes": r["vertices"]}}


def _median(values: list[float], failures: int) -> str:
    ranked = sorted(values) + [np.inf] * failures
    value = float(np.median(ranked)) if ranked else np.inf
    return "> limit" if not np.isfinite(value) else f"{value:.3g}"


def table(records: list[dict], labels: list[str]) -> list[str]:
    lines = ["| method | solved | median CPU (s) | median wall (s) | constraint evaluations | Jacobians | "
             "validity checks | sphere tests | samples | samples used | nodes |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for label in labels:
        runs = [r for r in records if r["method"] == label]
        solved = [r for r in runs if r["solved"]]
        ops = {k: f"{np.median([r['ops'][k] for r in solved]):,.0f}" if solved else "-"
               for k in ("fk", "jacobians", "collision_checks", "samples", "nodes")}
        spheres = [r.get("extras", {}).get("sphere_checks", 0) for r in solved]
        used = [r["extras"]["sampler"]["accepted"] for r in solved if "sampler" in r.get("extras", {})]
        failed = len(runs) - len(solved)
        lines.append(f"| {label} | {len(solved)}/{len(runs)} | {_median([r['cpu_s'] for r in solved], failed)} "
                     f"| {_median([r['time_s'] for r in solved], failed)} | {ops['fk']} | "
                     f"{ops['jacobians']} | {ops['collision_checks']} | "
                     f"{f'{np.median(spheres):,.0f}' if any(spheres) else '-'} | {ops['samples']} | "
                     f"{f'{np.median(used):,.0f}' if used else '-'} | {ops['nodes']} |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=30)
    parser.add_argument("--seed", type=int, default=0, help="the first seed (held-out seeds for tuning)")
    parser.add_argument("--time", type=float, default=10.0)
    parser.add_argument("--model", type=Path, help="a CVAE for the task (default: trained into OUT/cvae)")
    parser.add_argument("--set", dest="settings", action="append", default=[], metavar="KEY=VALUE",
                        help="our planner's settings (default: its defaults)")
    parser.add_argument("--ompl-tolerance", type=float, default=1e-4, help="OMPL's tolerance on |F| (the demo's)")
    parser.add_argument("--out", type=Path, default=Path("runs/sphere-demo"))
    parser.add_argument("--resume", action="store_true")
    args = parser.parse_args()
    if not PROGRAM.is_file():
        raise SystemExit(f"{PROGRAM} not found; build it with benchmarks/ompl_native/build.sh")
    if args.runs <= 0 or not args.time > 0:
        raise SystemExit("--runs and --time must be positive")
    set_threads()
    from manifoldgen.planning import planner_settings
    from manifoldgen.tasks import get_task

    args.out.mkdir(parents=True, exist_ok=True)
    settings = parse_settings(args.settings, None, planner_settings("rrtconnect"), "planner")
    model = args.model or ensure_model(args.out)
    tolerance = float(get_task("sphere").constraint.tolerance[0])
    experiment = Experiment("sphere", task="sphere", robot="point", time_limit=args.time, seed=args.seed,
                            planner_settings=settings)
    ours = [Method.parse(f"cvae=rrtconnect@cvae:{model}"), Method.parse("project=rrtconnect@project")]
    labels = [m.label for m in ours] + list(SPACES)
    runs_file = args.out / "runs.jsonl"
    config = {"experiment": experiment.to_dict(), "model": str(model), "ompl_tolerance": args.ompl_tolerance,
              "check_tolerance": tolerance, "program": str(PROGRAM)}
    if runs_file.is_file() and not args.resume:
        raise SystemExit(f"{runs_file} exists; pass --resume to continue it or choose another --out")
    config_file = args.out / "config.json"
    if runs_file.is_file() and config_file.is_file() and json.loads(config_file.read_text()) != json.loads(json.dumps(config)):
        raise SystemExit(f"{args.out} was made with other arguments (see its config.json); resume with the same "
                         "ones or choose another --out")
    config_file.write_text(json.dumps(config, indent=1) + "\n")
    done = {(r["method"], r["run"]) for r in read_records(runs_file)}
    with progress_bar("sphere demo", args.runs * len(labels)) as bar:
        for run in range(args.runs):
            for label in labels:
                if (label, run) in done:
                    bar.advance(1)
                    continue
                if label in SPACES:
                    record = {"method": label, "run": run, "seed": args.seed + run,
                              **run_native(SPACES[label], args.seed + run, args, tolerance)}
                else:
                    record = run_once(experiment, next(m for m in ours if m.label == label), run)
                    record.pop("path", None)
                with runs_file.open("a") as f:
                    f.write(json.dumps(record) + "\n")
                    f.flush()
                    os.fsync(f.fileno())
                bar.advance(1)
    records = [r for r in read_records(runs_file) if r["run"] < args.runs]
    print(f"OMPL's sphere demo: {args.runs} seeds per method (from {args.seed}), {args.time:g} s limit, methods interleaved per seed; "
          f"our planner settings {settings or 'default'}; OMPL tolerance {args.ompl_tolerance:g} on |F|, every path "
          f"checked every 0.005 m within {tolerance:g} m; runs in {runs_file}")
    print("\n".join(table(records, labels)))


if __name__ == "__main__":
    main()
