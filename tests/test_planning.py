"""Planners on problems with known answers; every returned path is checked densely."""

from __future__ import annotations

import json

import numpy as np
import pytest

from manifoldgen.data import collect
from manifoldgen.errors import ManifoldgenError
from manifoldgen.planning import PLANNERS, PlanResult, RRTConnectSettings, RRTSettings, shortcut, validate_path
from manifoldgen.planning.validate import densify
from manifoldgen.sampling import DatasetSampler, ProjectionSampler, UniformSampler
from manifoldgen.scene import get_scene
from planning_problems import BoxChecker, corridor_problem, sphere_problem

CASES = [(name, local) for name in PLANNERS for local in ("interpolate", "project")
         if not (name == "cbirrt" and local == "interpolate")]


def _planner(name, local, problem, seed=0, **settings):
    constraint, y, checker, start, goal = problem()
    if local == "interpolate" and problem is sphere_problem:
        settings.setdefault("range", 0.25)  # chords of the unit sphere sag L^2 / 8 < 0.0095
    cls = PLANNERS[name]
    sampler_type = UniformSampler if name == "cbirrt" else ProjectionSampler
    sampler = sampler_type(constraint, y, checker=checker, seed=seed)
    planner = cls(constraint, y, checker, sampler, local=local, seed=seed, settings=cls.settings_type(**settings))
    return planner, constraint, y, checker, start, goal


def _check(result: PlanResult, constraint, y, checker, start, goal):
    assert result.solved, result.extras
    assert np.allclose(result.path[0], start) and np.allclose(result.path[-1], goal)
    report = validate_path(result.path, constraint, y, checker, resolution=0.005)
    assert report.valid, report.reason
    assert report.worst_violation <= 1.0
    assert np.isclose(result.length, np.linalg.norm(np.diff(result.path, axis=0), axis=1).sum())
    return densify(result.path, 0.005)[0]


@pytest.mark.parametrize("name,local", CASES)
def test_sphere_path_crosses_the_equator_through_the_gap(name, local):
    planner, constraint, y, checker, start, goal = _planner(name, local, sphere_problem)
    states = _check(planner.solve(start, goal, 20.0), constraint, y, checker, start, goal)
    equator = states[np.abs(states[:, 2]) < 0.1]
    assert len(equator) and np.all(equator[:, 0] > 0.5) and np.all(np.abs(equator[:, 1]) < 0.25)


@pytest.mark.parametrize("name,local", CASES)
def test_corridor_path_goes_through_the_opening(name, local):
    planner, constraint, y, checker, start, goal = _planner(name, local, corridor_problem)
    states = _check(planner.solve(start, goal, 20.0), constraint, y, checker, start, goal)
    crossing = states[np.abs(states[:, 0]) <= 0.05]
    assert len(crossing) and np.all(crossing[:, 1] > 1.6)
    assert np.allclose(states[:, 2], 0.0, atol=0.01)


def test_same_seed_same_path_and_json_summary():
    first, *problem = _planner("rrtconnect", "interpolate", corridor_problem, seed=3)
    again, *_ = _planner("rrtconnect", "interpolate", corridor_problem, seed=3)
    a, b = first.solve(problem[3], problem[4], 20.0), again.solve(problem[3], problem[4], 20.0)
    np.testing.assert_array_equal(a.path, b.path)
    summary = json.loads(json.dumps(a.to_dict()))
    assert summary["solved"] and summary["waypoints"] == len(a.path) and "path" not in summary
    assert summary["planner"] == "rrtconnect" and summary["samples_drawn"] == a.samples_drawn > 0


def test_unsolvable_query_ends_at_the_time_limit_without_a_path():
    constraint, y, _, start, goal = corridor_problem()
    sealed = BoxChecker([([-0.05, -2.5, -0.5], [0.05, 2.5, 0.5])])
    planner = PLANNERS["rrtconnect"](constraint, y, sealed, ProjectionSampler(constraint, y, checker=sealed), seed=0)
    result = planner.solve(start, goal, 0.3)
    assert not result.solved and result.path.shape == (0, 3) and result.length == 0.0
    assert 0.3 <= result.time_s < 1.5


def test_coarse_checks_missing_a_thin_obstacle_are_caught_by_the_dense_validation():
    """At resolution 0.5 the straight checks step over a 2 cm slab; the final 0.005 check must
    refuse such paths (the offending edge is cut and the search goes on)."""
    constraint, y, _, start, goal = corridor_problem()
    slab = BoxChecker([([-0.01, -2.5, -0.5], [0.01, 1.9, 0.5])])
    sampler = ProjectionSampler(constraint, y, checker=slab, seed=0)
    planner = PLANNERS["rrtconnect"](constraint, y, slab, sampler, resolution=0.5, seed=0,
                                     settings=RRTConnectSettings(range=1.0))
    result = planner.solve(start, goal, 20.0)
    assert result.extras["rejected_paths"] > 0
    _check(result, constraint, y, slab, start, goal)


def test_shortcut_keeps_the_constraint_and_never_lengthens():
    planner, constraint, y, checker, start, goal = _planner("rrt", "interpolate", corridor_problem, seed=1)
    result = planner.solve(start, goal, 20.0)
    short = shortcut(result.path, planner.local, np.random.default_rng(0), attempts=200)
    assert np.allclose(short[0], start) and np.allclose(short[-1], goal)
    assert validate_path(short, constraint, y, checker).valid
    length = np.linalg.norm(np.diff(short, axis=0), axis=1).sum()
    assert length <= result.length + 1e-9 and len(short) <= len(result.path)


def test_pg_and_cbirrt_solve_the_wall_scene(panda_task):
    scene = get_scene(panda_task, "wall")
    constraint, y, checker = panda_task.constraint, scene.condition, scene.checker(panda_task.robot)
    data = collect(panda_task, 10_000, seed=2, conditions=[y], progress=False)
    pg = PLANNERS["rrtconnect"](constraint, y, checker, DatasetSampler(constraint, y, data.q, data.y, checker=checker),
                                seed=0)
    cbirrt = PLANNERS["cbirrt"](constraint, y, checker, UniformSampler(constraint, y, checker=checker), seed=0)
    for planner in (pg, cbirrt):
        result = planner.solve(scene.start, scene.goal, 30.0)
        _check(result, constraint, y, checker, scene.start, scene.goal)
    assert result.projections > 0 and result.extras["local"] == "project"


def test_bad_queries_are_refused_with_the_reason(panda_task):
    constraint, y, checker, start, goal = corridor_problem()
    planner = PLANNERS["rrt"](constraint, y, checker, ProjectionSampler(constraint, y), seed=0)
    with pytest.raises(ManifoldgenError, match="time limit must be a positive number of seconds, got 0"):
        planner.solve(start, goal, 0.0)
    with pytest.raises(ManifoldgenError, match=r"start configuration violates the constraint: .* 30.00 times"):
        planner.solve(start + [0, 0, 0.3], goal, 1.0)
    with pytest.raises(ManifoldgenError, match="goal configuration is in collision: point with box0"):
        planner.solve(start, np.zeros(3), 1.0)
    with pytest.raises(ManifoldgenError, match="rrt takes RRTSettings, got RRTConnectSettings"):
        PLANNERS["rrt"](constraint, y, checker, ProjectionSampler(constraint, y), settings=RRTConnectSettings())
    with pytest.raises(ManifoldgenError, match="goal_bias"):
        PLANNERS["rrt"](constraint, y, checker, ProjectionSampler(constraint, y), settings=RRTSettings(goal_bias=2))
    with pytest.raises(ManifoldgenError, match="rrtconnect needs a sampler"):
        PLANNERS["rrtconnect"](constraint, y, checker, None)


def test_cbirrt_without_a_sampler_draws_uniform_targets():
    constraint, y, checker, start, goal = corridor_problem()
    result = PLANNERS["cbirrt"](constraint, y, checker, None, seed=0).solve(start, goal, 20.0)
    _check(result, constraint, y, checker, start, goal)
