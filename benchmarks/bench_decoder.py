"""The learned sampler's decode in the compiled core (``manifoldgen_core.Decoder``) against torch's.

    python benchmarks/bench_decoder.py [MODEL_DIR] [--task pose --robot panda] [--rows 200000]
                                       [--plan maze --seed 100 --runs 100]

Prints, for a trained model (default: the shipped panda CVAE), at its mean condition:

- CPU µs per decoded row at batches of 32, 64, 256 and 1,024 rows (one thread, warm, median of repeats);
- the two laws compared: per configuration coordinate, |mean difference| / std between the core's rows and torch's,
  beside the same between two torch seeds, and the rows' constraint satisfaction rates;
- with ``--plan SCENE``: our planner on the task's scene (RRT-Connect on this model, sphere models on), each seed
  once with the core's decode and once with torch's (the same sampler with its core decoder removed): median
  collision queries (sphere tests plus sweep tests) and median CPU per query.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from manifoldgen.models import load_model, pretrained_model_dir
from manifoldgen.runtime import set_threads
from manifoldgen.tasks import get_task

BATCHES = (32, 64, 256, 1024)


def cost_per_row(decode, batch: int, repeats: int = 200) -> float:
    """Median CPU µs per row of ``decode(batch, i)`` over ``repeats`` calls (after one warm-up call)."""
    decode(batch, 0)
    times = []
    for i in range(repeats):
        began = time.process_time()
        decode(batch, i + 1)
        times.append(time.process_time() - began)
    return float(np.median(times)) / batch * 1e6


def plan(model_dir, task: str, robot: str, scene: str, seed: int, runs: int) -> None:
    from manifoldgen.bench.planning import Experiment, Method, build

    experiment = Experiment(scene, task=task, robot=robot, time_limit=10.0, planner_settings={"spheres": True})
    method = Method.parse(f"cvae=rrtconnect@cvae:{model_dir}")
    stats = {"core": ([], []), "torch": ([], [])}
    for s in range(seed, seed + runs):
        for source, (queries, cpu) in stats.items():
            planner, problem, _ = build(experiment, method, s)
            if source == "torch":
                planner.sampler.decoder, planner.sampler.generator = None, torch.Generator().manual_seed(s)
            before = planner.core.counts()
            began = time.process_time()
            planner.solve(problem.start, problem.goal, experiment.time_limit)
            cpu.append(time.process_time() - began)
            after = planner.core.counts()
            queries.append(sum(after[k] - before[k] for k in ("sphere_checks", "sweep_checks")))
    print(f"\n{scene}, seeds {seed}-{seed + runs - 1}: | decode | median collision queries | median CPU (s) |")
    for source, (queries, cpu) in stats.items():
        print(f"| {source} | {np.median(queries):,.0f} | {np.median(cpu):.4f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", nargs="?", default=str(pretrained_model_dir()))
    parser.add_argument("--task", default="pose")
    parser.add_argument("--robot", default="panda")
    parser.add_argument("--rows", type=int, default=200_000)
    parser.add_argument("--plan", metavar="SCENE", help="also plan the task's SCENE with each decode")
    parser.add_argument("--seed", type=int, default=100)
    parser.add_argument("--runs", type=int, default=100)
    args = parser.parse_args()
    set_threads()
    model = load_model(args.model)
    decoder = model.native_decoder()
    if decoder is None:
        raise SystemExit(f"{args.model}: no core decoder (the core is not built, or the network is not an MLP)")
    y = np.asarray(model.norm["y_mean"], float)

    print("| rows per decode | core (µs/row) | torch (µs/row) |\n|---|---|---|")
    for batch in BATCHES:
        core = cost_per_row(lambda b, i: decoder.sample(y, b, i), batch)
        torch_cost = cost_per_row(lambda b, i: model.sample(y, b, torch.Generator().manual_seed(i)), batch)
        print(f"| {batch:,} | {core:.2f} | {torch_cost:.2f} |")

    constraint = get_task(args.task, args.robot).constraint
    core_rows = decoder.sample(y, args.rows, 1)
    torch_rows = [model.sample(y, args.rows, torch.Generator().manual_seed(s)) for s in (1, 2)]
    spread = torch_rows[0].std(0)
    apart = {"core vs torch": np.abs(core_rows.mean(0) - torch_rows[0].mean(0)) / spread,
             "torch vs torch (another seed)": np.abs(torch_rows[1].mean(0) - torch_rows[0].mean(0)) / spread}
    print(f"\n{args.rows:,} rows at y = {y.tolist()}: |mean difference| / std per coordinate (max, median)")
    for label, gap in apart.items():
        print(f"  {label}: {gap.max():.4f}, {np.median(gap):.4f}")
    rates = [constraint.satisfied(rows, y).mean() for rows in (core_rows, *torch_rows)]
    print("  constraint satisfied: core %.4f, torch %.4f and %.4f" % tuple(rates))

    if args.plan:
        plan(args.model, args.task, args.robot, args.plan, args.seed, args.runs)


if __name__ == "__main__":
    main()
