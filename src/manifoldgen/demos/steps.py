"""The pipeline steps every demo runs: collect and train, sample, plan and re-check.

Each step prints its heading, does its work into the demo's output folder and adds its figures to
``figures`` (the dict the demo prints and returns).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch
from rich.console import Console

from manifoldgen.data import collect, default_rows
from manifoldgen.query import run_query, save_path
from manifoldgen.runtime import CANDIDATES, REFINE
from manifoldgen.scene import task_anchors
from manifoldgen.sampling import generate
from manifoldgen.selection import select_model
from manifoldgen.training import CHECKPOINT


def collect_and_train(task, seed: int, output: Path, console: Console, figures: dict, *, dataset: str) -> tuple:
    """The default pipeline's first two steps, as ``collect`` and ``train`` run them with no options: the
    default rows seeded half around every scene's start and goal into ``output/dataset``, then the candidate
    models trained, scored on held-out rows and raced on the task's scenes into ``output/model``
    (:func:`~manifoldgen.selection.select_model`). Returns the kept model and the sampler spec that stands for
    it (``model:DIR``: the projection sampler where projection won the race)."""
    console.rule("1. collect (defaults: rows seeded around the scenes' start and goal, and uniform)")
    start = time.perf_counter()
    rows = collect(task, default_rows(len(task.condition.grid)), seed, output / dataset, anchors=task_anchors(task))
    figures["rows"], figures["collect_s"] = len(rows), time.perf_counter() - start
    console.rule(f"2. train ({', '.join(CANDIDATES)} side by side, scored on held-out rows, raced on the scenes)")
    start = time.perf_counter()
    model, table, raced = select_model(rows, output / "model", seed=seed, task=task,
                                       resume=any((output / "model" / "candidates" / name / CHECKPOINT).exists()
                                                  for name in CANDIDATES))
    figures["train_s"], figures["kept"] = time.perf_counter() - start, ("projection" if model.mix == 1 else model.label)
    figures["candidates"], figures["race"] = table, raced
    return model, f"model:{output / 'model'}"


def race_line(figures: dict) -> str:
    """One line of what training kept and why: each raced entry's solved runs and median CPU."""
    race = ", ".join(f"{r['label']} {r['solved']}/{r['runs']} in {1000 * r['cpu']:.0f} ms" for r in figures["race"])
    return f"kept {figures['kept']}" + (f" (race on the scenes, median CPU: {race})" if race else "")


def sample_accuracy(model, task, y: np.ndarray, samples: int, seed: int, console: Console, figures: dict) -> None:
    """Draw ``samples`` rows at condition ``y (k,)`` and refine them; the share within tolerance, raw and refined."""
    console.rule("3. sample")
    start = time.perf_counter()
    raw, refined = generate(model, task.constraint, y, samples, torch.Generator().manual_seed(seed), REFINE)
    figures["sample_ms"] = (time.perf_counter() - start) * 1000  # model sampling and refinement
    figures["raw_valid"] = float(task.constraint.satisfied(raw, y).mean())
    figures["refined_valid"] = float(task.constraint.satisfied(refined, y).mean())


def plan_and_check(task, scene, sampler: str, seed: int, time_limit: float, path_file: Path, console: Console,
                   figures: dict, *, title: str, smooth: bool = False, settings: dict | None = None):
    """RRT-Connect on the scene's query with ``sampler``; the path saved to ``path_file`` and re-checked
    densely by :func:`run_query`. Returns (result, validation report)."""
    console.rule(f"4. {title}")
    result, meta = run_query(task, scene, sampler, "rrtconnect", seed=seed, time_limit=time_limit, smooth=smooth,
                             settings=settings)
    save_path(path_file, result, meta)
    report = meta["validation"]
    figures.update(solved=result.solved, plan_s=result.time_s, waypoints=len(result.path),
                   path_valid=bool(report.get("valid")), worst_violation=float(report.get("worst_violation", "nan")))
    return result, report
