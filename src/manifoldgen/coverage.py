"""Where a task will be queried, and how well a set of configurations covers it.

A task's *anchors* are the start and goal configurations of its scenes (end-effector targets solved onto
the manifold at the scene's condition; :func:`manifoldgen.scene.task_anchors` gathers them): the regions a
planner needs samples in. Collection seeds around them (:func:`anchor_seeds`); a *gap* (the distance from an
anchor to the nearest of a set of rows: a dataset's, a model's samples) tells a user, before planning, that the
rows miss an IK branch. *Modes* are the clusters of a set of rows (single linkage on a subsample, cut where
neighbours are several typical neighbour distances apart): IK branches separated by a gap in joint space.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

ANCHOR_SPREAD = 0.5  # rad: standard deviation of the seeds drawn around an anchor
MODE_ROWS = 1500  # rows clustered into modes (a subsample: single linkage is quadratic)
MODE_CUT = 3.0  # modes split where rows are more than this many median neighbour distances apart
MODE_SHARE = 0.02  # a cluster with fewer of the rows is not reported as a mode
FAR = 3.0  # a gap is a miss beyond this many of the reference rows' own gaps (and beyond MIN_MISS)
MIN_MISS = 0.5  # rad: gaps below this are never a miss (a planner's extension reaches them)


@dataclass
class Anchors:
    """Start and goal configurations ``q (A, n)`` of a task's scenes at their conditions ``y (A, k)``, and the
    ``scenes`` themselves as scene documents (JSON-ready dicts, start and goal solved to configurations)."""

    q: np.ndarray
    y: np.ndarray
    labels: list[str]
    scenes: list[dict] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.q)

    def to_meta(self) -> list[dict]:
        """JSON-ready: ``[{"label", "q", "condition"}, ...]`` (what a dataset's meta records)."""
        return [{"label": label, "q": q.tolist(), "condition": y.tolist()}
                for label, q, y in zip(self.labels, self.q, self.y)]


def anchor_seeds(anchors: Anchors, count: int, rng: np.random.Generator, robot) -> np.ndarray:
    """(count, n) seeds normal around anchors chosen at random (sd :data:`ANCHOR_SPREAD`), clipped to the limits."""
    centres = anchors.q[rng.integers(0, len(anchors), count)]
    return np.clip(centres + rng.normal(0.0, ANCHOR_SPREAD, centres.shape), robot.lower, robot.upper)


def gaps(rows: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(P,) distance from each of ``points (P, n)`` to the nearest of ``rows (R, n)`` (inf when there are none)."""
    points = np.atleast_2d(points)
    if not len(rows):
        return np.full(len(points), np.inf)
    out = np.empty(len(points))
    for i, p in enumerate(points):
        out[i] = np.sqrt(np.min(np.sum((rows - p) ** 2, axis=1)))
    return out


def spacing(rows: np.ndarray, seed: int = 0, count: int = 1000) -> float:
    """Median distance from a row of ``rows (R, n)`` to its nearest other row (on at most ``count`` rows)."""
    if len(rows) < 2:
        return float("inf")
    sub = rows if len(rows) <= count else rows[np.random.default_rng(seed).choice(len(rows), count, replace=False)]
    squares = np.sum(sub**2, axis=1)
    d2 = squares[:, None] + squares[None] - 2.0 * np.einsum("ij,kj->ik", sub, sub)  # no BLAS: its threads spin
    np.fill_diagonal(d2, np.inf)
    return float(np.sqrt(max(float(np.median(d2.min(axis=1))), 0.0)))


def missed(gap: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(P,) True where ``gap`` is a miss: far beyond the ``reference`` gap of rows that cover the point
    (e.g. a model's gap against the dataset's, or against projected uniform samples')."""
    return (np.asarray(gap) > FAR * np.asarray(reference)) & (np.asarray(gap) > MIN_MISS)


def model_gaps(sample, anchors: Anchors, count: int = 2000) -> list[dict]:
    """Per anchor: its ``label``, ``gap`` (rad) to the nearest of the ``count`` rows ``sample(y (k,), count)``
    draws at its condition, their ``spacing`` and ``missed`` (see :func:`missed`)."""
    report = []
    for label, a, y in zip(anchors.labels, anchors.q, anchors.y):
        rows = sample(y, count)
        gap, space = float(gaps(rows, a)[0]), spacing(rows)
        report.append({"label": label, "gap": round(gap, 4), "spacing": round(space, 4),
                       "missed": bool(missed(gap, space))})
    return report


def gap_lines(report: list[dict], what: str) -> list[str]:
    """One line per anchor of ``report`` (:func:`model_gaps`, or a dataset's ``coverage["anchors"]``)."""
    return [f"{'MISSED: ' if r['missed'] else ''}nearest {what} to {r['label']}: {r['gap']:.3f} rad "
            f"({what}s' own spacing {r['spacing']:.3f})" for r in report]


def anchors_from_meta(meta: dict) -> Anchors | None:
    """The anchors a dataset's meta records (a model's meta is its dataset's), or None. Every reader of a dataset or
    model (and training) has checked them first: :func:`manifoldgen.dataset.check_meta`."""
    found = meta.get("anchors") or []
    if not found:
        return None
    return Anchors(np.array([a["q"] for a in found], float), np.array([a["condition"] for a in found], float),
                   [str(a["label"]) for a in found])


def rows_at(q: np.ndarray, y_rows: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The rows of ``q (N, n)`` whose condition (``y_rows (N, k)``) is the one nearest ``y (k,)``."""
    values = np.unique(y_rows, axis=0)
    nearest = values[np.argmin(np.linalg.norm(values - np.asarray(y, float), axis=1))]
    return q[np.all(np.isclose(y_rows, nearest), axis=1)]


def modes(q: np.ndarray, seed: int = 0) -> list[dict]:
    """The modes of ``q (N, n)``, largest first: ``{"share": fraction of the rows, "centre": (n,) list}``,
    clustered on at most :data:`MODE_ROWS` rows (single linkage cut at :data:`MODE_CUT` median
    neighbour distances; clusters under :data:`MODE_SHARE` of the rows left out)."""
    from scipy.cluster.hierarchy import fcluster, linkage
    from scipy.spatial.distance import pdist, squareform

    if len(q) < 3:
        return [{"share": 1.0, "centre": np.mean(q, axis=0).tolist()}] if len(q) else []
    rows = q[np.random.default_rng(seed).choice(len(q), min(len(q), MODE_ROWS), replace=False)]
    distances = pdist(rows)
    square = squareform(distances)
    np.fill_diagonal(square, np.inf)
    cut = MODE_CUT * float(np.median(square.min(axis=1)))
    labels = fcluster(linkage(distances, "single"), cut, criterion="distance")
    found = []
    for label in np.unique(labels):
        members = rows[labels == label]
        if len(members) >= MODE_SHARE * len(rows):
            found.append({"share": len(members) / len(rows), "centre": members.mean(axis=0).tolist()})
    return sorted(found, key=lambda m: -m["share"])
