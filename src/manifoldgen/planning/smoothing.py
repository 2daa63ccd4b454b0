"""Shortcuts that keep the constraint: points along a path joined by the local planner (a straight motion, or a
projected walk where the chord leaves the manifold), each new stretch kept only when it is shorter and passes the
space's dense path check. The compiled core shortens its paths the same way (native/src/planner.cpp,
``Search::shorten``): the same points, from an additive recurrence instead of random draws."""

from __future__ import annotations

import time

import numpy as np

from manifoldgen.planning.local import LocalPlanner
from manifoldgen.planning.result import path_length

ALPHA = (0.7548776662466927, 0.5698402909980532)  # attempt a joins arc-length fractions sorted((a * ALPHA) mod 1)


def shortcut(path: np.ndarray, local: LocalPlanner, *, attempts: int = 100,
             time_limit: float = 1.0) -> tuple[np.ndarray, int]:
    """A path (K', n) no longer than ``path (K, n)``, with the same ends, valid wherever ``path`` was: attempt
    a = 1 .. ``attempts`` (until ``time_limit`` s) joins the points A, B at arc-length fractions u < v, the sorted
    (a * ALPHA) mod 1, through ``local.connect``; the stretch from the waypoint before A to the one after B replaces
    the old one when it is shorter and passes ``local.space.validate_path``; and how many stretches it replaced."""
    deadline = time.perf_counter() + time_limit
    out, kept = np.asarray(path, dtype=float), 0
    for a in range(1, attempts + 1):
        if len(out) < 3 or time.perf_counter() > deadline:
            break
        cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(out, axis=0), axis=1))])
        u, v = sorted(np.fmod(a * np.array(ALPHA), 1.0))
        start, end = u * cum[-1], v * cum[-1]
        i, j = (min(int(np.searchsorted(cum, t, side="right")) - 1, len(out) - 2) for t in (start, end))
        if i == j:
            continue  # one straight segment already
        A, B = _point(out, cum, i, start), _point(out, cum, j, end)
        if np.linalg.norm(B - A) >= end - start - 1e-9:
            continue
        piece = local.connect(A, B)
        if piece is None or path_length(np.concatenate([A[None], piece])) >= end - start - 1e-9:
            continue
        stretch = np.concatenate([out[i:i + 1], A[None], piece, out[j + 1:j + 2]])
        if local.space.validate_path(stretch).valid:
            joined = np.concatenate([out[:i], stretch, out[j + 2:]])
            keep = np.concatenate([[True], np.any(np.diff(joined, axis=0) != 0, axis=1)])
            out, kept = joined[keep], kept + 1
    return out, kept


def _point(path: np.ndarray, cum: np.ndarray, k: int, t: float) -> np.ndarray:
    """The point at arc length ``t`` on segment ``k`` (rows k, k + 1) of ``path``; ``cum`` the rows' arc lengths."""
    span = cum[k + 1] - cum[k]
    return path[k] + (path[k + 1] - path[k]) * ((t - cum[k]) / span if span > 0 else 0.0)
