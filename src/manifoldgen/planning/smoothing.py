"""Shortcut smoothing that keeps the constraint: random shortcuts through the local planner,
then the whole path re-validated densely by the space (the input comes back unchanged if it fails)."""

from __future__ import annotations

import time

import numpy as np

from manifoldgen.planning.local import LocalPlanner
from manifoldgen.planning.result import path_length


def shortcut(path: np.ndarray, local: LocalPlanner, rng: np.random.Generator, *, attempts: int = 100,
             time_limit: float = 1.0) -> np.ndarray:
    """Shorter path (K', n) with the same ends: ``attempts`` random pairs of waypoints are
    joined by ``local`` (a straight checked segment or a projected walk) when that is valid
    and shorter than the stretch it replaces."""
    deadline = time.perf_counter() + time_limit
    out = np.asarray(path, dtype=float)
    for _ in range(attempts):
        if len(out) < 3 or time.perf_counter() > deadline:
            break
        i, j = sorted(rng.choice(len(out), size=2, replace=False))
        if j - i < 2:
            continue
        waypoints = local.connect(out[i], out[j])
        if waypoints is None:
            continue
        if path_length(np.concatenate([out[i:i + 1], waypoints])) < path_length(out[i:j + 1]):
            out = np.concatenate([out[:i + 1], waypoints, out[j + 1:]])
    return out if local.space.validate_path(out).valid else np.asarray(path, dtype=float)
