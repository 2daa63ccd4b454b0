"""A user-written constraint trains as well as the built-in constraints of the same kind, and plans in
the compiled core through batched Python callbacks.

    python benchmarks/bench_user_constraint.py [--per-condition 2000] [--epochs 60]
    python benchmarks/bench_user_constraint.py --plan [--runs 10] [--time 30] [--sampler project|cvae]

The same manifold on xarm7, written twice: `examples/user_task/tool_down.py` (a user's ~20-line
constraint, Jacobian and training penalty from its one residual) and the built-in orientation + plane
constraints (`tool-down-xarm7-builtin.toml`). Same data size, seeds and CVAE settings; prints each
model's raw accuracy (fraction of samples within tolerance with no refinement) per condition and the
gap (target: within 10 points), with wall and CPU time.

``--plan``: the user constraint's task (xarm7, tool down at x = 0.4, the `open` scene's query with a box
between start and goal), RRT-Connect with the `project` sampler (or a CVAE trained first on the user
constraint with ``--per-condition`` and ``--epochs``: ``--sampler cvae``), the Python search against the compiled
core calling the user's residual and Jacobian (torch autograd) back in batches; seeds 0..runs-1, the two
interleaved per seed. Prints per search: solved, median CPU and wall time of a query, and the median
number of Python constraint calls and rows (configurations) per call.
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
parser.add_argument("--plan", action="store_true", help="time planning: Python search vs compiled core + callbacks")
parser.add_argument("--runs", type=int, default=10)
parser.add_argument("--time", type=float, default=30.0)
parser.add_argument("--sampler", choices=("project", "cvae"), default="project")
args = parser.parse_args()
set_torch_threads()


def count_calls(constraint):
    """Wrap ``constraint``'s residual, jacobian and inequality (instance attributes) to count Python calls, rows
    and the CPU seconds spent inside them; returns the running totals {"calls", "rows", "cpu"}."""
    totals, depth = {"calls": 0, "rows": 0, "cpu": 0.0}, [0]
    for name in ("residual", "jacobian", "inequality"):
        method = getattr(constraint, name)

        def counted(q, y, method=method):
            outer = not depth[0]  # the autograd Jacobian's own residual call is part of its call
            if outer:
                totals["calls"] += 1
                totals["rows"] += 1 if np.ndim(q) == 1 else len(q)
                began = time.process_time()
            depth[0] += 1
            try:
                return method(q, y)
            finally:
                depth[0] -= 1
                if outer:
                    totals["cpu"] += time.process_time() - began
        setattr(constraint, name, counted)
    return totals


def plan_bench():
    from dataclasses import replace

    from manifoldgen.planning import RRTConnect, RRTConnectSettings
    from manifoldgen.scene import Obstacle, Pose, get_scene
    from manifoldgen.space import ConstrainedSpace
    from manifoldgen.specs import make_sampler

    task = get_task(str(EXAMPLES / "tool-down-xarm7.toml"))
    scene = get_scene(task, "open")
    scene = replace(scene, obstacles=[Obstacle("block", "box", Pose([0.4, -0.08, -0.02]), size=[0.2, 0.06, 0.3])])
    sampler = "project"
    if args.sampler == "cvae":
        import tempfile
        folder = Path(tempfile.mkdtemp(prefix="bench-user-cvae-"))
        wall, cpu = time.perf_counter(), time.process_time()
        model = get_model_class("cvae")()
        model.fit(collect(task, args.per_condition, seed=0, progress=False), epochs=args.epochs, seed=0, progress=False)
        model.save(folder)
        sampler = f"cvae:{folder}"
        print(f"CVAE trained on the user constraint ({args.per_condition} rows per condition, {args.epochs} epochs): "
              f"{time.perf_counter() - wall:.0f} s wall, {time.process_time() - cpu:.0f} s CPU", flush=True)
    rows = {core: [] for core in ("python", "native")}
    for seed in range(args.runs):
        for core in rows:
            constraint = get_task(str(EXAMPLES / "tool-down-xarm7.toml")).constraint
            totals = count_calls(constraint)
            space = ConstrainedSpace(constraint, scene.condition, scene.checker(task.robot))
            planner = RRTConnect(space, make_sampler(sampler, space, seed), seed=seed,
                                 settings=RRTConnectSettings(core=core))
            totals.update(calls=0, rows=0, cpu=0.0)  # building the space evaluated the constraint once
            wall, cpu = time.perf_counter(), time.process_time()
            result = planner.solve(scene.start, scene.goal, args.time)
            cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
            assert result.extras["core"] == core, result.extras
            if result.solved:
                assert space.validate_path(result.path).valid
            rows[core].append((result.solved, cpu, wall, totals["calls"], totals["rows"], totals["cpu"] / cpu))
            print(f"seed {seed} {core:>6}: solved {result.solved}, {cpu:.2f} s CPU, {wall:.2f} s wall, "
                  f"{totals['calls']} Python constraint calls, {totals['rows']} rows, "
                  f"{totals['cpu']:.2f} s CPU inside them", flush=True)
    print("\n| search | solved | median CPU (s) | median wall (s) | Python constraint calls (median) | rows per call "
          "| CPU inside the user's constraint (median) |")
    print("|---|---|---|---|---|---|---|")
    for core, runs in rows.items():
        solved, cpu, wall, calls, n, inside = (np.array(c, float) for c in zip(*runs))
        print(f"| {'compiled core + callbacks' if core == 'native' else 'Python'} | {int(solved.sum())}/{len(runs)} "
              f"| {np.median(cpu):.2f} | {np.median(wall):.2f} | {np.median(calls):,.0f} "
              f"| {n.sum() / max(calls.sum(), 1):.1f} | {np.median(inside):.0%} |")


if args.plan:
    plan_bench()
    raise SystemExit(0)

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
