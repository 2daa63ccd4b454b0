"""The outcome of one planning query."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


REFUSALS = {"range": "no sample within range", "constraint": "constraint", "collision": "collision",
            "limits": "joint limits", "inequality": "inequality"}  # extras["rejected"] keys, in words


def engine(extras: dict) -> str:
    """Where a query's search ran, from its result's ``extras``, and why not in the compiled core when it
    could not: "compiled core", "Python search (why)", "C++ OMPL (its space)" or OMPL through its Python
    bindings."""
    where = extras.get("core")
    if where == "native":
        return "compiled core"
    if where == "python":
        return f"Python search ({extras['core_fallback']})" if extras.get("core_fallback") else \
            "Python search (asked for)"
    if "native_ops" in extras:
        return f"C++ OMPL ({extras.get('space', '?')})"
    if "ompl_status" in extras:
        return f"OMPL through its Python bindings ({extras.get('space', '?')})"
    return "Python search (this planner has no compiled version)"


def path_length(path: np.ndarray) -> float:
    """Joint-space length of a waypoint array ``(K, n)`` (sum of Euclidean segment lengths)."""
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()) if len(path) > 1 else 0.0


@dataclass
class PlanResult:
    """A planner's answer: ``path (K, n)`` dense waypoints, ``(0, n)`` when unsolved.

    time_s: wall time of ``solve``; iterations: planner loop iterations; samples_drawn:
    configurations taken from the sampler; projections: configurations projected onto the
    manifold (by the planner's local planner and by the sampler); length: joint-space path
    length; extras: planner-specific figures. Ours give ``nodes`` (tree sizes), ``rejected``
    (extensions refused, by reason: see ``REFUSALS``), ``rejected_paths`` (candidates that failed
    the dense validation), ``sampler`` (its stats over the query), ``evaluations`` and
    ``collision_checks`` (configurations checked), ``failure`` (why the sampler gave up), with
    ``shortcut`` set ``shortcuts`` and ``relaxed`` (shortcuts and relaxation moves kept) and ``found_length``
    (before them), with ``reuse`` set
    ``roadmap`` (``routed``: answered from earlier paths; ``nodes``; ``checks``: segments checked);
    :meth:`why` puts them in one line.
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

    def why(self) -> str:
        """One line for people: the outcome and, when unsolved, what held the search back (read
        from ``extras``: tree sizes, refused extensions by reason, samples, sampler failure)."""
        if self.solved:
            return (f"solved in {self.time_s:.3f} s: {len(self.path)} waypoints, length {self.length:.2f} rad, "
                    f"{self.samples_drawn} samples drawn")
        x, parts = self.extras, []
        if x.get("failure"):
            parts.append(f"the sampler failed: {x['failure']}")
        if x.get("nodes"):
            parts.append(f"{'trees' if len(x['nodes']) > 1 else 'tree'} of "
                         f"{' and '.join(str(n) for n in x['nodes'])} nodes")
        if "roadmap" in x:
            parts.append(f"roadmap of {x['roadmap']['nodes']} nodes, {x['roadmap']['edges']} edges")
        if "ompl_status" in x:
            parts.append(f"OMPL says {x['ompl_status']} with {x['vertices']} vertices")
        if x.get("reason"):
            parts.append(f"the path failed validation: {x['reason']}")
        parts.append(f"{self.samples_drawn} samples drawn")
        refused = sorted(((count, REFUSALS.get(reason, reason)) for reason, count in x.get("rejected", {}).items()
                          if count), reverse=True)
        if refused:
            parts.append("refused extensions: " + ", ".join(f"{what} {count}" for count, what in refused))
        if x.get("rejected_paths"):
            parts.append(f"{x['rejected_paths']} candidate paths failed the dense validation")
        if x.get("sampler_note"):
            parts.append(x["sampler_note"])
        return f"not solved in {self.time_s:.3f} s after {self.iterations} iterations: " + "; ".join(parts)

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
