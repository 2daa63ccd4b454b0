"""``manifoldgen demo pose``: the whole pipeline on the embedded default (panda, pose task, wall scene).

The default pipeline, every step at its defaults as a new user's task file gets them: collect (rows seeded
around the scenes' start and goal, and uniform), train (the candidate models scored on held-out rows and raced
on the task's scenes, the fastest kept), measure the kept model's samples, plan the wall scene's query with it,
validate the path densely and draw it.
"""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.table import Table

from manifoldgen.scene import get_scene
from manifoldgen.demos.steps import collect_and_train, plan_and_check, race_line, sample_accuracy
from manifoldgen.runtime import REFINE, set_threads
from manifoldgen.tasks import get_task
from manifoldgen.viz.path import plot_path
from manifoldgen.viz.snapshots import draw_snapshots

SAMPLES = 4000
# what the demo writes in its output folder (folders end in /)
OUTPUTS = ("pose.npz", "model/", "wall-path.npz", "wall-path.png", "wall-snapshots.png")


def run_demo(output: Path, seed: int, console: Console) -> dict:
    """Run the pipeline into ``output``; print and return the figures."""
    set_threads()
    output.mkdir(parents=True, exist_ok=True)
    task = get_task("pose", "panda")
    scene = get_scene(task, "wall")
    y = scene.condition
    figures: dict = {}

    model, sampler = collect_and_train(task, seed, output, console, figures, dataset="pose.npz")
    sample_accuracy(model, task, y, SAMPLES, seed, console, figures)
    result, report = plan_and_check(task, scene, sampler, seed, 30.0, output / "wall-path.npz", console, figures,
                                    title="plan in the wall scene", smooth=True)
    plot_path(result.path, task.robot, task.constraint.frame, scene, output / "wall-path.png",
              f"wall scene: RRT-Connect + {figures['kept']} sampler, shortcut, seed {seed}")
    if result.solved:
        draw_snapshots(result.path, task, scene, output / "wall-snapshots.png")

    table = Table("step", "result", title="manifoldgen demo: panda, pose task, wall scene")
    table.add_row("dataset", f"{figures['rows']} rows at heights "
                  f"{', '.join(f'{v:g}' for v in task.condition.values.ravel())} m in {figures['collect_s']:.1f} s")
    table.add_row("train", f"{race_line(figures)} in {figures['train_s']:.0f} s")
    table.add_row(f"{model.label} samples", f"{SAMPLES} samples at y = {y[0]:g} m, drawn and refined in "
                  f"{figures['sample_ms']:.0f} ms: "
                  f"{figures['raw_valid']:.1%} within tolerance raw, {figures['refined_valid']:.1%} after "
                  f"{REFINE} projection steps")
    table.add_row("plan", f"RRT-Connect, sampler {sampler}: "
                  f"{'solved' if result.solved else 'NOT solved'} in {result.time_s:.3f} s, "
                  f"{len(result.path)} waypoints, {result.samples_drawn} samples drawn")
    table.add_row("path check", f"{'valid' if figures['path_valid'] else 'INVALID'} at {report['resolution']} rad: worst constraint "
                  f"use {figures['worst_violation']:.2f} of tolerance, limits and collisions checked")
    table.add_row("files", f"{output / 'pose.npz'}, {output / 'model'}/, {output / 'wall-path.npz'}, "
                  f"{output / 'wall-path.png'}, {output / 'wall-snapshots.png'}")
    console.print(table)
    return figures
