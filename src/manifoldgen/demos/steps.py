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

from manifoldgen.data import collect
from manifoldgen.models import get_model_class
from manifoldgen.query import run_query, save_path
from manifoldgen.runtime import REFINE
from manifoldgen.sampling import generate
from manifoldgen.training import CHECKPOINT


def collect_and_train(task, per_condition: int, epochs: int, seed: int, output: Path, console: Console,
                      figures: dict, *, dataset: str, conditions: np.ndarray | None = None,
                      settings: dict | None = None, what: str = "", near_home: float = 0.0) -> object:
    """Collect ``per_condition`` rows per condition into ``output/dataset`` (``near_home`` > 0: seeds normal
    around the task's home, see :func:`~manifoldgen.data.collect`), train a CVAE into ``output/cvae``
    (resuming a stopped demo's training); returns the model."""
    console.rule(f"1. collect{what}")
    start = time.perf_counter()
    rows = collect(task, per_condition, seed, output / dataset, conditions=conditions, near_home=near_home)
    figures["rows"], figures["collect_s"] = len(rows), time.perf_counter() - start
    console.rule("2. train a CVAE")
    model = get_model_class("cvae")(**(settings or {}))
    interrupted = (output / "cvae" / CHECKPOINT).exists()  # a previous demo was stopped mid-training
    log = model.fit(rows, epochs=epochs, seed=seed, out=output / "cvae", resume=interrupted)
    figures["train_s"], figures["epochs"] = log.seconds, len(log.history)
    return model


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
