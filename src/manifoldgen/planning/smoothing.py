"""Shortening that keeps the constraint. Shortcuts: points along a path joined by the local planner (a straight
motion, or a projected walk where the chord leaves the manifold), each new stretch kept only when it is shorter and
passes the space's dense path check. Relaxation, after them: every inner waypoint pulled toward the midpoint of its
neighbours and projected back onto the manifold, kept when its two motions get shorter and those through the point
pulled twice as far pass the path check (the path keeps off the obstacles), the whole path checked at the end; it
pulls the path taut where no shortcut fits (a closed chain's detours). The compiled core shortens its paths the same
way (native/src/planner.cpp, ``Search::shorten`` and ``Search::relax``): the same points, from an additive recurrence
instead of random draws."""

from __future__ import annotations

import time

import numpy as np

from manifoldgen.planning.local import LocalPlanner
from manifoldgen.planning.result import path_length

ALPHA = (0.7548776662466927, 0.5698402909980532)  # attempt a joins arc-length fractions sorted((a * ALPHA) mod 1)
RELAX_GAIN, RELAX_SWEEPS = 0.01, 30  # relaxation stops after a sweep that gains less than RELAX_GAIN of the length


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
            out, kept = _without_repeats(np.concatenate([out[:i], stretch, out[j + 2:]])), kept + 1
    return out, kept


def _point(path: np.ndarray, cum: np.ndarray, k: int, t: float) -> np.ndarray:
    """The point at arc length ``t`` on segment ``k`` (rows k, k + 1) of ``path``; ``cum`` the rows' arc lengths."""
    span = cum[k + 1] - cum[k]
    return path[k] + (path[k + 1] - path[k]) * ((t - cum[k]) / span if span > 0 else 0.0)


def relax(path: np.ndarray, local: LocalPlanner, *, time_limit: float = 1.0) -> tuple[np.ndarray, int]:
    """``path (K, n)`` pulled taut, no longer, with the same ends, valid wherever it was: sweeps that pull each inner
    waypoint half way (else a quarter, else an eighth) toward its neighbours' midpoint, projected onto the manifold,
    keeping the move when its two motions get shorter and the motions through the point pulled twice as far pass
    ``local.space.validate_path`` (a probe that keeps the path off the obstacles it is pulled against: a taut path
    would graze them between the dense check's states); until a sweep gains less than ``RELAX_GAIN`` of the length
    (at most ``RELAX_SWEEPS``, until ``time_limit`` s). The whole path is then checked: should it fail, ``path``
    comes back as it was. Returns it and the moves kept."""
    deadline = time.perf_counter() + time_limit
    space, rows, moves = local.space, np.array(path, dtype=float), 0
    for _ in range(RELAX_SWEEPS):
        if len(rows) < 3 or time.perf_counter() > deadline:
            break
        gained = 0.0
        for i in range(1, len(rows) - 1):
            a, b = rows[i - 1], rows[i + 1]
            pull = 0.5 * (a + b) - rows[i]
            before = np.linalg.norm(rows[i] - a) + np.linalg.norm(b - rows[i])
            for share in (0.5, 0.25, 0.125):
                m = local.onto_manifold(rows[i] + share * pull)
                after = np.inf if m is None else np.linalg.norm(m - a) + np.linalg.norm(b - m)
                if after >= before:
                    continue
                probe = local.onto_manifold(rows[i] + 2 * share * pull)
                if probe is not None and space.validate_path(np.stack([a, probe, b])).valid:
                    rows[i], gained, moves = m, gained + before - after, moves + 1
                    break
        if gained < RELAX_GAIN * path_length(rows):
            break
    if not space.validate_path(rows).valid:
        return np.array(path, dtype=float), 0
    return _without_repeats(rows), moves


def _without_repeats(path: np.ndarray) -> np.ndarray:
    """``path (K, n)`` without the rows equal to the one before them (a shortcut's point on a waypoint, a waypoint
    pulled onto its neighbour)."""
    return path[np.concatenate([[True], np.any(np.diff(path, axis=0) != 0, axis=1)])]
