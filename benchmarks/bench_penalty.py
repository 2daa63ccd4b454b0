"""Cost of one training step's constraint penalty: the torch forward and backward pass of a task's residual.

    python benchmarks/bench_penalty.py balance-g1.toml balance-talos.toml dualarm-pr2.toml pose-kinova.toml

A task is a task file (here, in benchmarks/heldout/ or in src/manifoldgen/tasks/). For each, ``--rows``
configurations drawn inside the joint limits (float32, seed 0) at the task's home condition go through
``Constraint.penalty`` (its residual through the torch kinematics, as a model's training penalty calls it) and
back through autograd, repeated until 0.5 s of CPU. Prints one Markdown row per task: milliseconds of CPU and of wall
time per pass, and a hash of the gradient (equal hashes: the same bits), then the load average (the machine may be
shared). For a before/after figure, run it at each commit.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import time

import torch
from bench_defaults import task_path  # the same lookup of a task file's name

from manifoldgen.runtime import set_threads
from manifoldgen.tasks import load_task_file


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tasks", nargs="+", help="task files")
    parser.add_argument("--rows", type=int, default=512, help="rows per pass (a CVAE step penalises 2 x its batch)")
    args = parser.parse_args()
    set_threads()
    print("| task | joints | rows | CPU ms per pass | wall ms per pass | gradient hash |\n|---|---|---|---|---|---|")
    for name in args.tasks:
        task = load_task_file(task_path(name))
        robot, generator = task.robot, torch.Generator().manual_seed(0)
        lower, upper = (torch.as_tensor(bound, dtype=torch.float32) for bound in (robot.lower, robot.upper))
        q = (lower + (upper - lower) * torch.rand(args.rows, robot.n, generator=generator)).requires_grad_()
        y = torch.as_tensor(task.home_condition, dtype=torch.float32).expand(args.rows, -1)

        def step() -> None:
            q.grad = None
            task.constraint.penalty(q, y).sum().backward()

        for _ in range(3):
            step()
        passes, cpu, wall = 0, time.process_time(), time.perf_counter()
        while time.process_time() - cpu < 0.5:
            step()
            passes += 1
        cpu, wall = (time.process_time() - cpu) / passes, (time.perf_counter() - wall) / passes
        digest = hashlib.sha256(q.grad.numpy().tobytes()).hexdigest()[:12]
        print(f"| {name} | {robot.n} | {args.rows} | {1e3 * cpu:.2f} | {1e3 * wall:.2f} | {digest} |")
    print(f"\nload average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
