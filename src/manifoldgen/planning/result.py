"""The outcome of one planning query."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def path_length(path: np.ndarray) -> float:
    """Joint-space length of a waypoint array ``(K, n)`` (sum of Euclidean segment lengths)."""
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()) if len(path) > 1 else 0.0


@dataclass
class PlanResult:
    """A planner's answer: ``path (K, n)`` dense waypoints, ``(0, n)`` when unsolved.

    time_s: wall time of ``solve``; iterations: planner loop iterations; samples_drawn:
    configurations taken from the sampler; projections: configurations projected onto the
    manifold (by the planner's local planner and by the sampler); length: joint-space path
    length; extras: planner-specific figures (nodes, sampler stats, validation, ...).
    """

    solved: bool
    path: np.ndarray
    time_s: float
    iterations: int
    samples_drawn: int
    projections: int
    planner: str
    length: float
    extras: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready summary, without the path array."""
        return {"solved": bool(self.solved), "time_s": float(self.time_s), "iterations": int(self.iterations),
                "samples_drawn": int(self.samples_drawn), "projections": int(self.projections),
                "planner": self.planner, "length": float(self.length), "waypoints": int(len(self.path)),
                "extras": _plain(self.extras)}


def _plain(value):
    """Numpy scalars and arrays inside dicts and lists -> plain Python values."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value
