"""Datasets of constraint-satisfying configurations: collection and the .npz format.

File: ``q (N, n) float64``, ``y (N, k) float64`` and ``meta`` (JSON string) with
``format_version``, ``robot``, ``joints``, ``locked``, ``constraint``, ``seed`` (see
:meth:`manifoldgen.tasks.Task.meta`). Collection projects uniform seeds batch by batch;
batch ``b`` of condition ``c`` draws from ``default_rng([seed, c, b])``, and every
finished batch is saved under ``<out>.partial/``, so an interrupted run resumes where it
stopped and produces the same file as an uninterrupted one.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from manifoldgen.constraints import project
from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import check_output_path, load_npz, save_npz
from manifoldgen.progress import progress_bar
from manifoldgen.scene import task_checker
from manifoldgen.space import ConstrainedSpace
from manifoldgen.tasks import Task, task_from_meta

FORMAT_VERSION = 2  # 2: meta["task"] holds the full task spec


@dataclass
class Dataset:
    """Configurations ``q (N, n)`` satisfying the constraint at conditions ``y (N, k)``."""

    q: np.ndarray
    y: np.ndarray
    meta: dict

    def __len__(self) -> int:
        return len(self.q)

    def save(self, path: str | Path) -> None:
        save_npz(path, self.meta, q=self.q, y=self.y)

    @classmethod
    def load(cls, path: str | Path) -> Dataset:
        """Read and validate a dataset file (clear errors for truncated or foreign files)."""
        meta, arrays = load_npz(path, ("q", "y"))
        q, y = np.asarray(arrays["q"], float), np.asarray(arrays["y"], float)
        for key in ("format_version", "robot", "joints", "constraint"):
            if key not in meta:
                raise ManifoldgenError(f"{path}: meta lacks '{key}'; not a manifoldgen dataset")
        if q.ndim != 2 or y.ndim != 2 or len(q) != len(y) or q.shape[1] != len(meta["joints"]):
            raise ManifoldgenError(f"{path}: inconsistent shapes q {q.shape}, y {y.shape} for "
                                   f"{len(meta['joints'])} joints")
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(y))):
            raise ManifoldgenError(f"{path}: contains NaN or infinite values; recollect it")
        return cls(q, y, meta)

    def task(self) -> Task:
        """The task this dataset was collected for, rebuilt from its meta alone."""
        return task_from_meta(self.meta)

    def summary(self) -> dict:
        values, counts = np.unique(self.y, axis=0, return_counts=True)
        return {"rows": len(self), "robot": self.meta["robot"], "joints": len(self.meta["joints"]),
                "conditions": {json.dumps(v.tolist()): int(c) for v, c in zip(values, counts)}}


def collect(task: Task, per_condition: int, seed: int, out: str | Path | None = None, *,
            conditions: np.ndarray | None = None, batch: int = 2048, max_batches: int = 1000,
            give_up: int = 20, progress: bool = True) -> Dataset:
    """Collect ``per_condition`` valid rows at each condition value (default: the task's).

    A condition that yields no valid row in its first ``give_up`` batches is an error.
    With ``out``, batches are saved as they finish and the dataset is written atomically
    at the end; rerunning the same command after an interruption resumes.
    """
    if per_condition <= 0:
        raise ManifoldgenError(f"--per-condition must be a positive number of rows, got {per_condition}")
    k = task.condition.k
    values = task.condition.grid if conditions is None or not k else np.asarray(conditions, float).reshape(-1, k)
    meta = {"format_version": FORMAT_VERSION, **task.meta(), "seed": seed,
            "per_condition": per_condition, "method": "uniform seeds + damped least-squares projection"}
    partial = None
    if out is not None:
        out = check_output_path(out)
        partial = out.with_name(out.name + ".partial")
        _prepare_partial(partial, meta)
    checker = task_checker(task)
    qs, ys = [], []
    with progress_bar("collecting", total=per_condition * len(values), enabled=progress) as bar:
        for c, y in enumerate(values):
            space = ConstrainedSpace(task.constraint, y, checker)
            got = []
            for b in range(max_batches):
                if sum(len(g) for g in got) >= per_condition:
                    break
                rows = _load_batch(partial, c, b)
                if rows is None:
                    rng = np.random.default_rng([seed, c, b])
                    res = project(task.constraint, task.robot.sample_uniform(batch, rng), y)
                    rows = res.q[space.valid(res.q)]
                    if partial is not None:
                        save_npz(partial / f"c{c}-b{b}.npz", {}, q=rows)
                got.append(rows)
                if b + 1 >= give_up and not sum(len(g) for g in got):
                    break
                bar.advance(min(len(rows), per_condition - sum(len(g) for g in got[:-1])))
            q = np.concatenate(got)[:per_condition]
            if len(q) < per_condition:
                raise ManifoldgenError(f"only {len(q)} valid rows at condition {y.tolist()} after "
                                       f"{len(got)} batches of {batch}; the condition is probably unreachable: "
                                       f"choose values inside {task.condition.describe()}")
            qs.append(q)
            ys.append(np.broadcast_to(y, (per_condition, len(y))))
    dataset = Dataset(np.concatenate(qs), np.concatenate(ys).copy(), meta)
    if out is not None:
        dataset.save(out)
        shutil.rmtree(partial, ignore_errors=True)
    return dataset


def _prepare_partial(partial: Path, meta: dict) -> None:
    """Keep a previous run's batches only if it ran with the same settings."""
    stamp = partial / "meta.json"
    if partial.exists():
        try:
            same = json.loads(stamp.read_text()) == json.loads(json.dumps(meta))
        except (OSError, ValueError):
            same = False
        if not same:
            shutil.rmtree(partial)
    partial.mkdir(parents=True, exist_ok=True)
    if not stamp.exists():
        stamp.write_text(json.dumps(meta))


def _load_batch(partial: Path | None, c: int, b: int) -> np.ndarray | None:
    if partial is None or not (partial / f"c{c}-b{b}.npz").exists():
        return None
    try:
        return load_npz(partial / f"c{c}-b{b}.npz", ("q",))[1]["q"]
    except ManifoldgenError:
        return None  # a batch cut off mid-write is recomputed
