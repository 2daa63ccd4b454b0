"""``manifoldgen demo dualarm``: the paper's dual-arm tray (Section V-B) end to end on the PR2.

The default pipeline, every step at its defaults: collect configurations holding the tray at every trained
wrist distance and pitch (seeded around the scenes' start and goal, and uniform), train (the candidate models
raced on the task's scenes, the fastest kept), measure the kept model's samples at the scene's (d, pitch), plan
the ``tray-over`` query (carry the tray over a block on a table) with it, validate the path densely
(closed chain, tray orientation, limits, robot and tray collisions) and draw the tray's trace and
robot snapshots.
"""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.table import Table

from manifoldgen.demos.steps import collect_and_train, plan_and_check, race_line, sample_accuracy
from manifoldgen.runtime import REFINE, set_threads
from manifoldgen.scene import get_scene
from manifoldgen.targets import constrained_frame
from manifoldgen.tasks import get_task
from manifoldgen.viz.path import plot_path
from manifoldgen.viz.snapshots import draw_snapshots

SAMPLES = 2000
TIME_LIMIT = 60.0
# what the demo writes in its output folder (folders end in /)
OUTPUTS = ("dualarm.npz", "model/", "tray-over.npz", "tray-over.png", "tray-over-snapshots.png")


def run_demo(output: Path, seed: int, console: Console) -> dict:
    """Run the pipeline into ``output``; print and return the figures."""
    set_threads()
    output.mkdir(parents=True, exist_ok=True)
    task = get_task("dualarm", "pr2")
    scene = get_scene(task, "tray-over")
    y = scene.condition
    figures: dict = {}

    model, sampler = collect_and_train(task, seed, output, console, figures, dataset="dualarm.npz")
    sample_accuracy(model, task, y, SAMPLES, seed, console, figures)
    result, report = plan_and_check(task, scene, sampler, seed, TIME_LIMIT, output / "tray-over.npz", console,
                                    figures, title="plan tray-over", smooth=True)
    plot_path(result.path, task.robot, constrained_frame(task.constraint), scene, output / "tray-over.png",
              f"tray-over: RRT-Connect + {figures['kept']} sampler, shortcut, seed {seed}")
    if result.solved:
        draw_snapshots(result.path, task, scene, output / "tray-over-snapshots.png")

    table = Table("step", "result", title="manifoldgen demo: pr2, dual-arm tray, tray-over scene")
    table.add_row("dataset", f"{figures['rows']} rows at {len(task.condition.grid)} (d, pitch) values in "
                  f"{figures['collect_s']:.1f} s")
    table.add_row("train", f"{race_line(figures)} in {figures['train_s']:.0f} s")
    table.add_row(f"{model.label} samples", f"{SAMPLES} samples at (d, pitch) = ({y[0]:g} m, {y[1]:g} rad), drawn and "
                  f"refined in {figures['sample_ms']:.0f} ms: {figures['raw_valid']:.1%} within tolerance raw, "
                  f"{figures['refined_valid']:.1%} after {REFINE} projection steps")
    table.add_row("plan", f"RRT-Connect, sampler {sampler}: {'solved' if result.solved else 'NOT solved'} in "
                  f"{result.time_s:.3f} s, {len(result.path)} waypoints, {result.samples_drawn} samples drawn")
    table.add_row("path check", f"{'valid' if figures['path_valid'] else 'INVALID'} at {report['resolution']} rad: "
                  f"worst constraint use {figures['worst_violation']:.2f} of tolerance; limits and collisions of "
                  "the robot and the tray checked")
    table.add_row("files", f"{output / 'dualarm.npz'}, {output / 'model'}/, {output / 'tray-over.npz'}, "
                  f"{output / 'tray-over.png'}, {output / 'tray-over-snapshots.png'}")
    console.print(table)
    return figures
