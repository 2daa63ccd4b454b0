"""``manifoldgen demo balance``: whole-body balance on the embedded default (centauro, balance task, reach scene).

Collect a small dataset of statically stable configurations (feet fixed, CoM inside the support
polygon; seeds drawn around the stance, as the benchmark's data), train a CVAE briefly with the residual
and CoM-margin penalties, measure its samples' accuracy, plan the left hand's reach past the post in front
of the bottle with the learned sampler, validate the path densely, check static stability state by state (CoM over the support polygon, feet on their spots),
execute the path quasi-statically in MuJoCo (does the robot stay upright?) and draw the snapshots with the support polygon and the CoM's ground projection (paper Fig. 6).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from manifoldgen.data import collect
from manifoldgen.demos.steps import plan_and_check, sample_accuracy
from manifoldgen.models import get_model_class
from manifoldgen.physics import balance_feet, check_path
from manifoldgen.runtime import REFINE, set_threads
from manifoldgen.scene import get_scene
from manifoldgen.stability import path_stability
from manifoldgen.tasks import get_task
from manifoldgen.training import CHECKPOINT
from manifoldgen.viz.path import plot_path
from manifoldgen.viz.snapshots import draw_snapshots

PER_CONDITION = 800  # x 3 pelvis heights around the scene's 0.8 m
HEIGHTS = [[0.75], [0.8], [0.85]]
NEAR_HOME = 1.0  # rad: seeds normal around the stance (uniform seeds rarely converge with the wheels upright)
EPOCHS = 40
CVAE = {"latent": 8, "hidden": [256, 256]}  # as the benchmark's: a latent of 3 covers too little of the 39 joints
SAMPLES = 2000
# what the demo writes in its output folder (folders end in /)
OUTPUTS = ("balance.npz", "cvae/", "reach-path.npz", "reach-path.png", "reach-snapshots.png")
HAND = "arm1_8"  # centauro's left hand
PLANNER = {"pool": 32, "pool_batch": 64}  # few stepping stones: the learned samples are dear (39 joints, projected)


def _collect_and_train(task, seed: int, output: Path, console: Console, figures: dict):
    """Collect :data:`PER_CONDITION` rows at each of :data:`HEIGHTS` (seeds around the stance) into
    ``output/balance.npz`` and train a :data:`CVAE` into ``output/cvae`` (resuming a stopped demo's training).
    Not the default pipeline: with 39 joints the default 10,000 rows take about ten minutes of one core to
    collect (17 rows per CPU second, seeds around the scene's start and goal and uniform)."""
    console.rule("1. collect stable configurations (seeds around the stance)")
    start = time.perf_counter()
    rows = collect(task, PER_CONDITION, seed, output / "balance.npz", conditions=np.array(HEIGHTS),
                   near_home=NEAR_HOME)
    figures["rows"], figures["collect_s"] = len(rows), time.perf_counter() - start
    console.rule("2. train a CVAE")
    model = get_model_class("cvae")(**CVAE)
    interrupted = (output / "cvae" / CHECKPOINT).exists()  # a previous demo was stopped mid-training
    log = model.fit(rows, epochs=EPOCHS, seed=seed, out=output / "cvae", resume=interrupted)
    figures["train_s"], figures["epochs"] = log.seconds, len(log.history)
    return model


def run_demo(output: Path, seed: int, console: Console) -> dict:
    """Run the pipeline into ``output``; print and return the figures."""
    set_threads()
    output.mkdir(parents=True, exist_ok=True)
    task = get_task("balance", "centauro")
    scene = get_scene(task, "reach")  # the hand's target pose solved on the balance manifold
    y = scene.condition
    figures: dict = {}

    model = _collect_and_train(task, seed, output, console, figures)
    sample_accuracy(model, task, y, SAMPLES, seed, console, figures)  # feet, height AND CoM inside
    sampler = f"cvae:{output / 'cvae'},refine={REFINE},batch=256"
    result, report = plan_and_check(task, scene, sampler, seed, 30.0, output / "reach-path.npz", console, figures,
                                    title="plan the reach", settings=PLANNER)
    plot_path(result.path, task.robot, HAND, scene, output / "reach-path.png",
              f"reach scene: RRT-Connect + CVAE sampler, seed {seed}")

    console.rule("5. static stability along the path")
    if result.solved:
        stability = path_stability(task.constraint, result.path)
        figures["stability"] = stability.to_dict()
        draw_snapshots(result.path, task, scene, output / "reach-snapshots.png")

    if result.solved:
        console.rule("6. execute the path in MuJoCo")
        physics = check_path(task.robot, result.path, balance_feet(task.constraint.spec()), progress=True)
        figures["physics"] = physics.to_dict()

    table = Table("step", "result", title="manifoldgen demo: centauro, balance task, reach scene")
    table.add_row("dataset", f"{figures['rows']} stable configurations at pelvis heights "
                  f"{', '.join(f'{v:g}' for v in np.ravel(HEIGHTS))} m in {figures['collect_s']:.1f} s (seeds around the "
                  f"stance, sd {NEAR_HOME:g} rad)")
    table.add_row("CVAE", f"{figures['epochs']} epochs in {figures['train_s']:.0f} s")
    table.add_row("sample accuracy", f"{SAMPLES} samples at pelvis height {y[0]:g} m: {figures['raw_valid']:.1%} "
                  f"balanced within tolerance raw, {figures['refined_valid']:.1%} after {REFINE} projection steps")
    table.add_row("plan", f"RRT-Connect, sampler {sampler}: {'solved' if result.solved else 'NOT solved'} in "
                  f"{result.time_s:.3f} s, {len(result.path)} waypoints, {result.samples_drawn} samples drawn")
    table.add_row("path check", f"{'valid' if figures['path_valid'] else 'INVALID'} at {report['resolution']} rad: "
                  f"worst constraint use {figures['worst_violation']:.2f} of tolerance, CoM margin, limits, collisions")
    if "stability" in figures:
        s = figures["stability"]
        table.add_row("static stability", f"{s['states']} states: CoM outside the support polygon in {s['unstable']} "
                      f"({s['unstable_fraction']:.1%}), at least {100 * s['min_depth']:.1f} cm inside; feet moved "
                      f"at most {1000 * s['max_foot_drift']:.1f} mm")
    if "physics" in figures:
        p = figures["physics"]
        table.add_row("physics (MuJoCo)", f"{'UPRIGHT' if p['upright'] else 'FELL' if p['fell'] else 'TILTED'}: base tilt "
                      f"at most {p['max_tilt_deg']:.2f} deg, feet slipped at most {1000 * p['max_slip_m']:.1f} mm, base "
                      f"drifted {100 * p['base_drift_m']:.1f} cm ({p['simulated_s']:.0f} s simulated)")
    table.add_row("files", f"{output / 'balance.npz'}, {output / 'cvae'}/, {output / 'reach-path.npz'}, "
                  f"{output / 'reach-path.png'}, {output / 'reach-snapshots.png'}")
    console.print(table)
    return figures
