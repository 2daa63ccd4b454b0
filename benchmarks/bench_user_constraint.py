"""A user-written constraint trains as well as the built-in constraints of the same kind.

    python benchmarks/bench_user_constraint.py [--per-condition 2000] [--epochs 60]

The same manifold on xarm7, written twice: `examples/user_task/tool_down.py` (a user's ~20-line
constraint, Jacobian and training penalty from its one residual) and the built-in orientation + plane
constraints (`tool-down-xarm7-builtin.toml`). Same data size, seeds and CVAE settings; prints each
model's raw accuracy (fraction of samples within tolerance with no refinement) per condition and the
gap (target: within 10 points), with wall and CPU time.
"""

import argparse
import time
from pathlib import Path

import numpy as np
import torch

from manifoldgen.data import collect
from manifoldgen.models import get_model_class
from manifoldgen.runtime import set_torch_threads
from manifoldgen.tasks import get_task

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "user_task"
parser = argparse.ArgumentParser()
parser.add_argument("--per-condition", type=int, default=2000)
parser.add_argument("--epochs", type=int, default=60)
parser.add_argument("--samples", type=int, default=4000)
args = parser.parse_args()
set_torch_threads()

rates = {}
for label, file in (("user", "tool-down-xarm7.toml"), ("built-in", "tool-down-xarm7-builtin.toml")):
    task = get_task(str(EXAMPLES / file))
    wall, cpu = time.perf_counter(), time.process_time()
    data = collect(task, args.per_condition, seed=0, progress=False)
    model = get_model_class("cvae")()
    model.fit(data, epochs=args.epochs, seed=0, progress=False)
    gen = torch.Generator().manual_seed(0)
    rates[label] = {float(y[0]): float(task.constraint.satisfied(model.sample(y, args.samples, gen), y).mean())
                    for y in task.condition.grid}
    print(f"{label:>8}: {len(data)} rows, CVAE {args.epochs} epochs; raw accuracy "
          + ", ".join(f"x={y:g}: {r:.1%}" for y, r in rates[label].items())
          + f"; mean {np.mean(list(rates[label].values())):.1%} "
          f"({time.perf_counter() - wall:.0f} s wall, {time.process_time() - cpu:.0f} s CPU)")
gap = 100 * (np.mean(list(rates["built-in"].values())) - np.mean(list(rates["user"].values())))
print(f"gap (built-in minus user): {gap:+.1f} points (target: within 10)")
