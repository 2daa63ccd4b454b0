"""The compiled search's nearest-neighbour index (a k-d tree) against brute force.

The index must be exact, ties included (the lowest row wins, as a linear scan's), so that the search
makes the same decisions as with linear scans.
"""

from __future__ import annotations

import numpy as np
import pytest

from manifoldgen.core_extension import core_module

core = core_module()
pytestmark = pytest.mark.skipif(core is None, reason="the compiled core is not built")


def brute(points: np.ndarray, alive: np.ndarray, queries: np.ndarray, radius: float):
    """(nearest alive row, lowest on ties, -1 if none; any alive row within radius) per query."""
    d = ((queries[:, None, :] - points[None]) ** 2).sum(axis=2)
    d[:, ~alive] = np.inf
    nearest = np.where(np.isfinite(d).any(axis=1), d.argmin(axis=1), -1)  # argmin: the first minimum
    return nearest, (d <= radius**2).any(axis=1)


@pytest.mark.parametrize("n", [1, 2, 3, 7])
def test_nearest_matches_brute_force(n):
    rng = np.random.default_rng(n)
    points = rng.normal(size=(600, n))
    if n == 3:  # on a unit sphere, as the sphere demo's nodes
        points /= np.linalg.norm(points, axis=1, keepdims=True)
    points[100:130] = points[0]  # duplicates: ties go to the lowest row
    points[200:260] = np.round(points[200:260], 1)  # repeated coordinates: splits with equal values
    alive = rng.random(len(points)) > 0.2
    queries = np.concatenate([rng.normal(size=(300, n)) * 1.5, points[:50], 3 * rng.normal(size=(20, n))])
    radius = 0.6
    nearest, within = core.nearest_queries(np.ascontiguousarray(points), alive.tolist(), queries, radius)
    want_nearest, want_within = brute(points, alive, queries, radius)
    np.testing.assert_array_equal(nearest, want_nearest)
    np.testing.assert_array_equal(within, want_within)
    assert 0 < np.mean(within) < 1  # both answers occur


def test_nearest_with_no_row_alive():
    points = np.random.default_rng(0).normal(size=(40, 3))
    nearest, within = core.nearest_queries(points, [False] * 40, points[:5], 10.0)
    assert list(nearest) == [-1] * 5 and not any(within)

