"""The dataset container and its ``.npz`` file: configurations ``q (N, n) float64`` satisfying a constraint at
conditions ``y (N, k) float64``, and ``meta`` (a JSON string in the file) naming the robot, joints, constraint
and task they were made for (see :meth:`manifoldgen.tasks.Task.meta`; :mod:`manifoldgen.data` collects them)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from manifoldgen.errors import ManifoldgenError, file_reader
from manifoldgen.io import load_npz, save_npz

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
        return cls(q, y, meta)

    def summary(self) -> dict:
        values, counts = np.unique(self.y, axis=0, return_counts=True)
        return {"rows": len(self), "robot": self.meta["robot"], "joints": len(self.meta["joints"]),
                "conditions": {json.dumps(v.tolist()): int(c) for v, c in zip(values, counts)}}
