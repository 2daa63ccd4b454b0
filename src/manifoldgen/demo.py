"""``manifoldgen demo``: the pipeline end to end on the embedded default (panda, pose task)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from rich.console import Console

from manifoldgen.data import collect
from manifoldgen.tasks import get_task


def run_demo(output: Path, seed: int, console: Console) -> dict:
    """Collect a small panda pose dataset and print its summary; returns the figures."""
    output.mkdir(parents=True, exist_ok=True)
    task = get_task("pose", "panda")
    start = time.perf_counter()
    dataset = collect(task, 500, seed, output / "pose.npz")
    elapsed = time.perf_counter() - start
    residual = np.abs(task.constraint.residual(dataset.q, dataset.y))
    figures = {"rows": len(dataset), "collect_s": elapsed,
               "valid_fraction": float(task.constraint.satisfied(dataset.q, dataset.y).mean()),
               "max_position_error_m": float(residual[:, 0].max()),
               "max_orientation_error_rad": float(residual[:, 1:].max())}
    console.print(f"[bold]panda pose dataset[/]: {figures['rows']} rows at heights "
                  f"{', '.join(f'{v:g}' for v in task.condition.values.ravel())} m in {elapsed:.1f} s -> "
                  f"{output / 'pose.npz'}")
    console.print(f"  within tolerance: {figures['valid_fraction']:.1%}; worst errors "
                  f"{figures['max_position_error_m']:.1e} m, {figures['max_orientation_error_rad']:.1e} rad")
    return figures
