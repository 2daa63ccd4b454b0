"""Paths for testing validate_path(certify=True) against the state-by-state check: polylines through projected
random states, whose chords leave the manifold between the waypoints (the farther apart, the more)."""

from __future__ import annotations

import numpy as np


def manifold_polylines(space, core, reference: np.ndarray, spread: float, seed: int, count: int = 6,
                       waypoints: int = 4) -> list[np.ndarray]:
    """Polylines (waypoints, n) through random states around ``reference`` projected by ``core``, ``count`` at
    each of the spreads ``spread`` / (8, 2, 0.5, 0.25)."""
    robot, rng, paths = space.robot, np.random.default_rng(seed), []
    for scale in (8, 2, 0.5, 0.25):
        q = np.clip(reference + rng.normal(0, spread / scale, (4 * count * waypoints, robot.n)), robot.lower,
                    robot.upper)
        q, converged, _, _ = core.project(np.ascontiguousarray(q))
        q = q[converged.astype(bool)][: count * waypoints]
        paths += [np.ascontiguousarray(p) for p in q[: len(q) // waypoints * waypoints].reshape(-1, waypoints, robot.n)]
    return paths


def compare_certified(core, paths: list[np.ndarray]) -> tuple[set[int], dict[bool, int]]:
    """Assert that validate_path(certify=True)'s verdict, first invalid state, reason, segment and state count equal
    the state-by-state ones and its worst (over the evaluated states) is at most theirs, on every path; the reasons
    seen and the states evaluated (certify: False / True)."""
    reasons, evaluations = set(), {False: 0, True: 0}
    for path in paths:
        report = {}
        for certify in (False, True):
            before = core.counts()["evaluations"]
            report[certify] = core.validate_path(path, certify=certify)
            evaluations[certify] += core.counts()["evaluations"] - before
        exact, certified = report[False], report[True]
        assert certified[0] == exact[0] and certified[2:] == exact[2:]
        assert certified[1] <= exact[1]
        reasons.add(exact[3])
    return reasons, evaluations
