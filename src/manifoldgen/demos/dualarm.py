"""``manifoldgen demo dualarm``: the paper's dual-arm tray (Section V-B) end to end on the PR2.

Collect configurations holding the tray level (pitch 0) at every trained wrist distance, train a CVAE
briefly, measure its samples' accuracy at the scene's (d, pitch), plan the ``tray-over`` query (carry
the tray over a block on a table) with RRT-Connect and the learned sampler, validate the path densely
(closed chain, tray orientation, limits, robot and tray collisions) and draw the tray's trace and
robot snapshots.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from manifoldgen.demos.steps import collect_and_train, plan_and_check, sample_accuracy
from manifoldgen.runtime import REFINE, set_torch_threads
from manifoldgen.scene import get_scene
from manifoldgen.targets import constrained_frame
from manifoldgen.tasks import get_task
from manifoldgen.viz.path import plot_path
from manifoldgen.viz.snapshots import draw_snapshots

PER_CONDITION = 1000
EPOCHS = 20
SAMPLES = 2000
TIME_LIMIT = 60.0


def demo_conditions(task) -> np.ndarray:
    """(V, 2) the task's training conditions at pitch 0: every wrist distance, the tray level."""
    grid = task.condition.grid
    return grid[np.isclose(grid[:, 1], 0.0)]


def run_demo(output: Path, seed: int, console: Console) -> dict:
    """Run the pipeline into ``output``; print and return the figures."""
    set_torch_threads()
    output.mkdir(parents=True, exist_ok=True)
    task = get_task("dualarm", "pr2")
    scene = get_scene(task, "tray-over")
    y = scene.condition
    conditions = demo_conditions(task)
    figures: dict = {}

    model = collect_and_train(task, PER_CONDITION, EPOCHS, seed, output, console, figures, dataset="dualarm.npz",
                              conditions=conditions)
    sample_accuracy(model, task, y, SAMPLES, seed, console, figures)
    sampler = f"cvae:{output / 'cvae'},refine={REFINE}"
    result, report = plan_and_check(task, scene, sampler, seed, TIME_LIMIT, output / "tray-over.npz", console,
                                    figures, title="plan tray-over", smooth=True)
    plot_path(result.path, task.robot, constrained_frame(task.constraint), scene, output / "tray-over.png",
              f"tray-over: RRT-Connect + CVAE sampler, shortcut, seed {seed}")
    if result.solved:
        draw_snapshots(result.path, task, scene, output / "tray-over-snapshots.png")

    table = Table("step", "result", title="manifoldgen demo: pr2, dual-arm tray, tray-over scene")
    table.add_row("dataset", f"{figures['rows']} rows at d = {', '.join(f'{v:g}' for v in conditions[:, 0])} m, "
                  f"pitch 0, in {figures['collect_s']:.1f} s")
    table.add_row("CVAE", f"{figures['epochs']} epochs in {figures['train_s']:.0f} s")
    table.add_row("sample accuracy", f"{SAMPLES} samples at (d, pitch) = ({y[0]:g} m, {y[1]:g} rad), drawn and "
                  f"refined in {figures['sample_ms']:.0f} ms: {figures['raw_valid']:.1%} within tolerance raw, "
                  f"{figures['refined_valid']:.1%} after {REFINE} projection steps")
    table.add_row("plan", f"RRT-Connect, sampler {sampler}: {'solved' if result.solved else 'NOT solved'} in "
                  f"{result.time_s:.3f} s, {len(result.path)} waypoints, {result.samples_drawn} samples drawn")
    table.add_row("path check", f"{'valid' if figures['path_valid'] else 'INVALID'} at {report['resolution']} rad: "
                  f"worst constraint use {figures['worst_violation']:.2f} of tolerance; limits and collisions of "
                  "the robot and the tray checked")
    table.add_row("files", f"{output / 'dualarm.npz'}, {output / 'cvae'}/, {output / 'tray-over.npz'}, "
                  f"{output / 'tray-over.png'}, {output / 'tray-over-snapshots.png'}")
    console.print(table)
    return figures
