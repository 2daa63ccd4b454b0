"""Local planners and path validation on problems with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from manifoldgen.errors import ManifoldgenError
from manifoldgen.planning import make_local, validate_path
from manifoldgen.planning.validate import densify, state_problem
from planning_problems import BoxChecker, SphereConstraint, sphere_problem

ONE = np.array([1.0])


def _on_sphere(*angles):
    """Points (B, 3) on the unit sphere at polar angles (rad) in the x-z plane."""
    a = np.asarray(angles, float)
    return np.stack([np.sin(a), np.zeros_like(a), -np.cos(a)], axis=1)


def test_densify_spacing_and_ends():
    path = np.array([[0.0, 0, 0], [1.0, 0, 0], [1.0, 0.02, 0]])
    states, segment = densify(path, 0.1)
    assert np.allclose(states[0], path[0]) and np.allclose(states[-1], path[-1])
    assert np.max(np.linalg.norm(np.diff(states, axis=0), axis=1)) <= 0.1 + 1e-12
    assert segment[0] == 0 and segment[-1] == 1 and len(states) == 10 + 1 + 1


def test_interpolate_accepts_short_chords_and_refuses_long_ones():
    constraint = SphereConstraint()
    local = make_local("interpolate", constraint, ONE, None, 0.01, margin=0.0, partial=False)
    a, b_short, b_long = _on_sphere(0.3, 0.5, 1.3)
    # a chord of length L sags by L^2 / 8 below the unit sphere: 0.2^2/8 = 0.005 < 0.01 < 1^2/8
    waypoints, reached = local.steer(a, b_short)
    assert reached and np.allclose(waypoints[-1], b_short)
    assert validate_path(np.stack([a, b_short]), constraint, ONE, None).valid
    assert local.connect(a, b_long) is None
    report = validate_path(np.stack([a, b_long]), constraint, ONE, None)
    assert not report.valid and report.segment == 0 and report.worst_violation > 1
    assert "violates the constraint" in report.reason


def test_interpolate_truncates_and_keeps_the_valid_prefix():
    constraint = SphereConstraint()
    a, near, far = _on_sphere(0.0, 0.12, 1.5)
    strict = make_local("interpolate", constraint, ONE, None, 0.01, margin=0.0, partial=False)
    waypoints, reached = strict.steer(a, near, max_distance=0.06)
    assert not reached and np.isclose(np.linalg.norm(waypoints[-1] - a), 0.06)
    # toward a far target the chord leaves the sphere at once: |F| ~ 0.68 x distance
    assert len(strict.steer(a, far, max_distance=0.06)[0]) == 0
    partial = make_local("interpolate", constraint, ONE, None, 0.01, margin=0.0, partial=True)
    waypoints, reached = partial.steer(a, far)
    assert not reached and len(waypoints) == 1
    assert constraint.violation(waypoints, ONE)[0] <= 1.0
    # the kept prefix is straight from a and valid all along
    assert validate_path(np.stack([a, waypoints[-1]]), constraint, ONE, None, resolution=0.001).valid


def test_project_walks_along_the_manifold_round_an_obstacle_free_arc():
    constraint = SphereConstraint()
    local = make_local("project", constraint, ONE, None, 0.02, step=0.1)
    a, b = _on_sphere(0.2, 2.0)
    waypoints, reached = local.steer(a, b)
    assert reached and np.allclose(waypoints[-1], b)
    path = np.concatenate([a[None], waypoints])
    assert validate_path(path, constraint, ONE, None).valid
    assert local.projections >= len(waypoints) - 1
    assert np.max(np.linalg.norm(np.diff(path, axis=0), axis=1)) <= 2 * 0.1


def test_local_planners_stop_at_obstacles():
    constraint, y, checker, _, _ = sphere_problem()
    a, b = _on_sphere(1.2, 1.9)  # crosses the equator at x > 0 ... but y = 0 lies in the free gap
    blocked = BoxChecker([([0.85, -0.1, -0.1], [1.1, 0.1, 0.1])])
    for name in ("interpolate", "project"):
        local = make_local(name, constraint, y, blocked, 0.01, step=0.05)
        waypoints, reached = local.steer(a, b, max_distance=np.inf)
        assert not reached
        if len(waypoints):
            path = np.concatenate([a[None], waypoints])
            assert validate_path(path, constraint, y, blocked).valid
    free = make_local("project", constraint, y, checker, 0.01, step=0.05)
    assert free.connect(a, b) is not None


def test_validate_reports_collision_and_limits():
    constraint, y, checker, _, _ = sphere_problem()
    a, b = np.array([[0.8, 0.5, -0.12], [0.8, 0.5, 0.12]]) / np.linalg.norm([0.8, 0.5, 0.12])  # through the band
    report = validate_path(np.stack([a, b]), constraint, y, checker)
    assert not report.valid and "collision" in report.reason and "box" in report.reason
    outside = np.array([2.5, 0.0, 0.0])
    assert "outside the joint limits: x = 2.5000" in state_problem(outside, constraint, np.array([2.5]), None)
    bad = validate_path(np.zeros((2, 4)), constraint, y, None)
    assert not bad.valid and "shape" in bad.reason


def test_local_planner_bad_names_and_settings():
    constraint = SphereConstraint()
    with pytest.raises(ManifoldgenError, match="unknown local planner 'straight'; known: interpolate, project"):
        make_local("straight", constraint, ONE, None, 0.05)
    with pytest.raises(ManifoldgenError, match="resolution > 0"):
        make_local("interpolate", constraint, ONE, None, 0.0)
