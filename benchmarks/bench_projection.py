"""Projection from uniform seeds, per robot: success rate and median iterations to 1e-6.

    python benchmarks/bench_projection.py [--seeds 5000]
"""

import argparse
import time

import numpy as np

from manifoldgen.constraints import project
from manifoldgen.runtime import set_threads
from manifoldgen.tasks import TASKS, get_task

parser = argparse.ArgumentParser()
parser.add_argument("--seeds", type=int, default=5000)
args = parser.parse_args()
set_threads()  # as every command: torch's and numpy's BLAS threads sized for this machine

print("| robot | joints | success (to 1e-6, <= 50 it.) | median iterations | time per 1k seeds |")
print("|---|---|---|---|---|")
for robot in TASKS["pose"]:
    task = get_task("pose", robot)
    rng = np.random.default_rng(0)
    values = task.condition.values[rng.integers(0, len(task.condition.values), args.seeds)]
    seeds = task.robot.sample_uniform(args.seeds, rng)
    start = time.perf_counter()
    res = project(task.constraint, seeds, values, tol=1e-6, max_iters=50)
    elapsed = time.perf_counter() - start
    print(f"| {robot} | {task.robot.n} | {res.converged.mean():.1%} | {np.median(res.iterations[res.converged]):.0f} "
          f"| {elapsed / args.seeds * 1e6:.0f} ms |")
