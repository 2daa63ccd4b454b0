"""``manifoldgen demo pose``: the whole pipeline on the embedded default (panda, pose task, wall scene).

Collect a small dataset, train a CVAE briefly, measure its samples' accuracy, plan the wall
scene's query with the learned sampler (refined by a few projection steps), validate the
path densely and draw it.
"""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.table import Table

from manifoldgen.scene import get_scene
from manifoldgen.demos.steps import collect_and_train, plan_and_check, sample_accuracy
from manifoldgen.runtime import REFINE, set_torch_threads
from manifoldgen.tasks import get_task
from manifoldgen.viz.path import plot_path
from manifoldgen.viz.snapshots import draw_snapshots

PER_CONDITION = 1000
EPOCHS = 20
# A lighter residual penalty than the cvae default: in a 20-epoch run the default's penalty
# narrows the samples before they spread over the manifold, and the wall query needs coverage.
CVAE_SETTINGS = {"residual_weight": 0.05, "recon_residual_weight": 0.05}
SAMPLES = 4000


def run_demo(output: Path, seed: int, console: Console) -> dict:
    """Run the pipeline into ``output``; print and return the figures."""
    set_torch_threads()
    output.mkdir(parents=True, exist_ok=True)
    task = get_task("pose", "panda")
    scene = get_scene(task, "wall")
    y = scene.condition
    figures: dict = {}

    model = collect_and_train(task, PER_CONDITION, EPOCHS, seed, output, console, figures, dataset="pose.npz",
                              settings=CVAE_SETTINGS)
    sample_accuracy(model, task, y, SAMPLES, seed, console, figures)
    sampler = f"cvae:{output / 'cvae'},refine={REFINE}"
    result, report = plan_and_check(task, scene, sampler, seed, 30.0, output / "wall-path.npz", console, figures,
                                    title="plan in the wall scene", smooth=True)
    plot_path(result.path, task.robot, task.constraint.frame, scene, output / "wall-path.png",
              f"wall scene: RRT-Connect + CVAE sampler, shortcut, seed {seed}")
    if result.solved:
        draw_snapshots(result.path, task, scene, output / "wall-snapshots.png")

    table = Table("step", "result", title="manifoldgen demo: panda, pose task, wall scene")
    table.add_row("dataset", f"{figures['rows']} rows at heights "
                  f"{', '.join(f'{v:g}' for v in task.condition.values.ravel())} m in {figures['collect_s']:.1f} s")
    table.add_row("CVAE", f"{figures['epochs']} epochs in {figures['train_s']:.0f} s")
    table.add_row("sample accuracy", f"{SAMPLES} samples at y = {y[0]:g} m, drawn and refined in "
                  f"{figures['sample_ms']:.0f} ms: "
                  f"{figures['raw_valid']:.1%} within tolerance raw, {figures['refined_valid']:.1%} after "
                  f"{REFINE} projection steps")
    table.add_row("plan", f"RRT-Connect, sampler {sampler}: "
                  f"{'solved' if result.solved else 'NOT solved'} in {result.time_s:.3f} s, "
                  f"{len(result.path)} waypoints, {result.samples_drawn} samples drawn")
    table.add_row("path check", f"{'valid' if figures['path_valid'] else 'INVALID'} at {report['resolution']} rad: worst constraint "
                  f"use {figures['worst_violation']:.2f} of tolerance, limits and collisions checked")
    table.add_row("files", f"{output / 'pose.npz'}, {output / 'cvae'}/, {output / 'wall-path.npz'}, "
                  f"{output / 'wall-path.png'}, {output / 'wall-snapshots.png'}")
    console.print(table)
    return figures
