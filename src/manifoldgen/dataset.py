"""The dataset container and its ``.npz`` file: configurations ``q (N, n) float64`` satisfying a constraint at
conditions ``y (N, k) float64``, and ``meta`` (a JSON string in the file) naming the robot, joints, constraint
and task they were made for (see :meth:`manifoldgen.tasks.Task.meta`; :mod:`manifoldgen.data` collects them)."""

from __future__ import annotations

import difflib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from manifoldgen.errors import ManifoldgenError, file_reader, short
from manifoldgen.io import load_npz, save_npz

FORMAT_VERSION = 2  # 2: meta["task"] holds the full task spec
TASK_KEYS = ("task", "robot", "joints", "locked", "floating_base", "constraint", "tolerance", "condition")
META_KEYS = ("format_version", *TASK_KEYS, "seed", "per_condition", "method", "near_home", "anchors", "scenes",
             "coverage",  # a dataset's; a sample file's besides:
             "dataset_seed", "rows", "refine", "generated_by", "raw_valid_rate", "refined_valid_rate")


@dataclass
class Dataset:
    """Configurations ``q (N, n)`` satisfying the constraint at conditions ``y (N, k)``."""

    q: np.ndarray
    y: np.ndarray
    meta: dict

    def __len__(self) -> int:
        return len(self.q)

    def save(self, path: str | Path) -> None:
        """Write the file (atomic); rows with NaN or infinite values are refused (no reader would take them)."""
        if not (np.isfinite(self.q).all() and np.isfinite(self.y).all()):
            raise ManifoldgenError(f"dataset rows hold NaN or infinite values; {path} not written")
        save_npz(path, self.meta, q=self.q, y=self.y)

    @classmethod
    @file_reader
    def load(cls, path: str | Path) -> Dataset:
        """Read and validate a dataset file (clear errors for truncated or foreign files)."""
        meta, arrays = load_npz(path, ("q", "y"))
        if any(arrays[k].dtype.kind not in "fiu" for k in ("q", "y")):
            raise ManifoldgenError(f"{path}: q and y must be arrays of numbers, got {arrays['q'].dtype} and "
                                   f"{arrays['y'].dtype}; regenerate the file")
        q, y = np.asarray(arrays["q"], float), np.asarray(arrays["y"], float)
        for key in ("format_version", "robot", "joints", "constraint"):
            if key not in meta:
                raise ManifoldgenError(f"{path}: meta lacks '{key}'; not a manifoldgen dataset")
        if meta["format_version"] != FORMAT_VERSION:
            raise ManifoldgenError(f"{path}: dataset format {meta['format_version']!r} is not the one this version "
                                   f"reads ({FORMAT_VERSION}); collect it again")
        if not isinstance(meta["robot"], str) or not isinstance(meta["joints"], list) \
                or not all(isinstance(j, str) for j in meta["joints"]):
            raise ManifoldgenError(f"{path}: meta 'robot' must be a name and 'joints' a list of joint names; the file "
                                   "was edited or is damaged: collect it again")
        if q.ndim != 2 or y.ndim != 2 or len(q) != len(y) or q.shape[1] != len(meta["joints"]):
            raise ManifoldgenError(f"{path}: inconsistent shapes q {q.shape}, y {y.shape} for "
                                   f"{len(meta['joints'])} joints")
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(y))):
            raise ManifoldgenError(f"{path}: contains NaN or infinite values; recollect it")
        extra = sorted(set(arrays) - {"q", "y"})
        if extra:
            raise ManifoldgenError(f"{path}: unknown array '{extra[0]}' beside q and y; the file was edited: "
                                   "collect it again")
        check_meta(meta, y.shape[1], str(path))
        return cls(q, y, meta)

    def summary(self) -> dict:
        values, counts = np.unique(self.y, axis=0, return_counts=True)
        return {"rows": len(self), "robot": self.meta["robot"], "joints": len(self.meta["joints"]),
                "conditions": {json.dumps(v.tolist()): int(c) for v, c in zip(values, counts)}}


def check_meta(meta: dict, k: int, where: str) -> None:
    """Refuse a dataset's (or a model's) ``meta`` with an unknown key, copies of its task (``robot``, ``locked``,
    ``floating_base``, ``constraint``) that contradict ``meta["task"]``, a ``tolerance`` or ``condition`` (for ``k``
    condition columns) of the wrong form, or ``scenes`` and ``anchors`` that no reader could use. ``where``: the
    file, for messages. (:func:`manifoldgen.provenance.check_task_copies` compares the rest once the task is built.)"""
    def bad(why: str) -> ManifoldgenError:
        return ManifoldgenError(f"{where}: meta {why}; the file was edited or is damaged: make it again")

    unknown = next((key for key in meta if key not in META_KEYS), None)
    if unknown is not None:
        close = difflib.get_close_matches(str(unknown), META_KEYS, n=1)
        raise bad(f"has an unknown key '{unknown}'" + (f" (did you mean '{close[0]}'?)" if close else ""))
    task = meta.get("task")
    if isinstance(task, dict):
        identity = task.get("robot")
        copies = {"robot": identity.get("name") if isinstance(identity, dict) else identity,
                  "locked": task.get("locked"), "floating_base": task.get("floating_base"),
                  "constraint": task.get("constraint")}
        for key, value in copies.items():
            if key in meta and meta[key] != value:
                raise bad(f"'{key}' {short(meta[key])} contradicts its task's {short(value)}")
    tolerance = meta.get("tolerance", [1.0])
    if not (isinstance(tolerance, list) and tolerance and all(
            isinstance(t, (int, float)) and not isinstance(t, bool) and 0 < t < float("inf") for t in tolerance)):
        raise bad(f"'tolerance' {short(tolerance)} is not a list of positive numbers")
    condition = meta.get("condition", {"names": [""] * k, "units": [""] * k, "values": [[0.0] * k]})
    if not (isinstance(condition, dict) and set(condition) == {"names", "units", "values"}
            and all(isinstance(condition[key], list) and len(condition[key]) == k
                    and all(isinstance(v, str) for v in condition[key]) for key in ("names", "units"))
            and isinstance(condition["values"], list) and condition["values"]
            and all(isinstance(row, list) and len(row) == k and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in row) for row in condition["values"])):
        raise bad(f"'condition' must hold names, units and value rows for y's {k} condition columns")
    _check_scenes(meta, where, bad)


def _check_scenes(meta: dict, where: str, bad) -> None:
    """Refuse ``scenes`` that are not a list of scene documents (objects; read whole by the race that plans them,
    :func:`manifoldgen.selection.select_model`, before any training) and ``anchors`` that are not labelled
    configurations."""
    scenes, anchors = meta.get("scenes", []), meta.get("anchors", [])
    if not isinstance(scenes, list) or not isinstance(anchors, list):
        raise bad("'scenes' and 'anchors' must be lists")
    if not all(isinstance(doc, dict) for doc in scenes):
        raise bad("'scenes' must hold scene documents (JSON objects)")
    for i, anchor in enumerate(anchors):
        if not (isinstance(anchor, dict) and set(anchor) == {"label", "q", "condition"} and isinstance(
                anchor["label"], str) and all(isinstance(anchor[key], list) and all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) for v in anchor[key])
                    for key in ("q", "condition"))):
            raise bad(f"anchors[{i}] must hold a 'label', its configuration 'q' and its 'condition'")
