"""Local planners and path validation on problems with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from manifoldgen.errors import ManifoldgenError
from manifoldgen.planning import make_local
from manifoldgen.space import ConstrainedSpace, ValidationSettings, densify
from planning_problems import BoxChecker, SphereConstraint, sphere_problem

ONE = np.array([1.0])


def _space(checker=None, margin=0.05, resolution=0.005):
    return ConstrainedSpace(SphereConstraint(), ONE, checker, ValidationSettings(resolution, margin))


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
    space = _space(margin=0.0)
    local = make_local("interpolate", space, resolution=0.01, partial=False)
    a, b_short, b_long = _on_sphere(0.3, 0.5, 1.3)
    # a chord of length L sags by L^2 / 8 below the unit sphere: 0.2^2/8 = 0.005 < 0.01 < 1^2/8
    waypoints, reached = local.steer(a, b_short)
    assert reached and np.allclose(waypoints[-1], b_short)
    assert space.validate_path(np.stack([a, b_short])).valid
    assert local.connect(a, b_long) is None and space.stop == "constraint"
    report = space.validate_path(np.stack([a, b_long]))
    assert not report.valid and report.segment == 0 and report.worst_violation > 1
    assert "violates the constraint" in report.reason


def test_interpolate_truncates_and_keeps_the_valid_prefix():
    a, near, far = _on_sphere(0.0, 0.12, 1.5)
    strict = make_local("interpolate", _space(margin=0.0), resolution=0.01, partial=False)
    waypoints, reached = strict.steer(a, near, max_distance=0.06)
    assert not reached and np.isclose(np.linalg.norm(waypoints[-1] - a), 0.06)
    # toward a far target the chord leaves the sphere at once: |F| ~ 0.68 x distance
    assert len(strict.steer(a, far, max_distance=0.06)[0]) == 0
    partial = make_local("interpolate", _space(margin=0.0), resolution=0.01, partial=True)
    waypoints, reached = partial.steer(a, far)
    assert not reached and len(waypoints) == 1
    assert partial.space.violation(waypoints)[0] <= 1.0
    # the kept prefix is straight from a and valid all along
    assert _space(resolution=0.001).validate_path(np.stack([a, waypoints[-1]])).valid


@pytest.mark.parametrize("name", ["project", "auto"])
def test_walks_follow_the_manifold_round_an_obstacle_free_arc(name):
    """``project`` walks; ``auto`` walks where the straight chord leaves the sphere."""
    space = _space()
    local = make_local(name, space, resolution=0.02, step=0.1)
    a, b = _on_sphere(0.2, 2.0)
    waypoints, reached = local.steer(a, b)
    assert reached and np.allclose(waypoints[-1], b)
    path = np.concatenate([a[None], waypoints])
    assert space.validate_path(path).valid
    assert local.projections >= len(waypoints) - 1
    assert np.max(np.linalg.norm(np.diff(path, axis=0), axis=1)) <= 2 * 0.1
    assert make_local("interpolate", space, resolution=0.02).connect(a, b) is None


def test_local_planners_stop_at_obstacles():
    constraint, y, checker, _, _ = sphere_problem()
    a, b = _on_sphere(1.2, 1.9)  # crosses the equator at x > 0 ... but y = 0 lies in the free gap
    blocked = ConstrainedSpace(constraint, y, BoxChecker([([0.85, -0.1, -0.1], [1.1, 0.1, 0.1])]))
    for name in ("auto", "interpolate", "project"):
        local = make_local(name, blocked, resolution=0.01, step=0.05)
        waypoints, reached = local.steer(a, b, max_distance=np.inf)
        assert not reached
        if len(waypoints):
            path = np.concatenate([a[None], waypoints])
            assert blocked.validate_path(path).valid
    assert blocked.stopped["collision"] > 0
    free = make_local("project", ConstrainedSpace(constraint, y, checker), resolution=0.01, step=0.05)
    assert free.connect(a, b) is not None


def test_validate_reports_collision_and_limits():
    constraint, y, checker, _, _ = sphere_problem()
    space = ConstrainedSpace(constraint, y, checker)
    a, b = np.array([[0.8, 0.5, -0.12], [0.8, 0.5, 0.12]]) / np.linalg.norm([0.8, 0.5, 0.12])  # through the band
    report = space.validate_path(np.stack([a, b]))
    assert not report.valid and "collision" in report.reason and "box" in report.reason
    outside = np.array([2.5, 0.0, 0.0])
    assert "outside the joint limits: x = 2.5000" in ConstrainedSpace(constraint, [2.5]).problem(outside)
    bad = space.validate_path(np.zeros((2, 4)))
    assert not bad.valid and "shape" in bad.reason


def test_local_planner_bad_names_and_settings():
    with pytest.raises(ManifoldgenError, match="unknown local planner 'straight'; known: auto, interpolate, project"):
        make_local("straight", _space())
    with pytest.raises(ManifoldgenError, match="resolution > 0"):
        make_local("interpolate", _space(), resolution=0.0)
