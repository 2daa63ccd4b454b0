"""Planners on problems with known answers; every returned path is checked densely."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from manifoldgen.constraints import ConstraintSet, OrientationConstraint, PlaneConstraint, project
from manifoldgen.data import collect
from manifoldgen.errors import ManifoldgenError
from manifoldgen.planning import PLANNERS, PlanResult, RRTConnectSettings, RRTSettings, relax, shortcut
from manifoldgen.planning.base import Tree
from manifoldgen.robot import Robot
from manifoldgen.sampling import DatasetSampler, ProjectionSampler, UniformSampler
from manifoldgen.scene import get_scene
from manifoldgen.space import ConstrainedSpace, densify
from planning_problems import BoxChecker, corridor_problem, sphere_problem

CASES = [(name, local) for name in PLANNERS.names() for local in ("auto", "interpolate", "project")
         if not (name == "cbirrt" and local != "project")]


def _planner(name, local, problem, seed=0, **settings):
    constraint, y, checker, start, goal = problem()
    if local == "interpolate" and problem is sphere_problem:
        settings.setdefault("range", 0.25)  # chords of the unit sphere sag L^2 / 8 < 0.0095
    cls = PLANNERS.get(name)
    space = ConstrainedSpace(constraint, y, checker)
    sampler = (UniformSampler if name == "cbirrt" else ProjectionSampler)(space, seed=seed)
    planner = cls(space, sampler, local=local, seed=seed, settings=cls.settings_type(**settings))
    return planner, space, start, goal


def _check(result: PlanResult, space, start, goal):
    assert result.solved, result.why()
    assert np.allclose(result.path[0], start) and np.allclose(result.path[-1], goal)
    report = ConstrainedSpace(space.constraint, space.y, space.checker).validate_path(result.path)
    assert report.valid, report.reason
    assert report.worst_violation <= 1.0 and report.resolution == 0.005
    assert np.isclose(result.length, np.linalg.norm(np.diff(result.path, axis=0), axis=1).sum())
    return densify(result.path, 0.005)[0]


@pytest.mark.parametrize("name,local", CASES)
def test_sphere_path_crosses_the_equator_through_the_gap(name, local):
    planner, space, start, goal = _planner(name, local, sphere_problem)
    states = _check(planner.solve(start, goal, 20.0), space, start, goal)
    equator = states[np.abs(states[:, 2]) < 0.1]
    assert len(equator) and np.all(equator[:, 0] > 0.5) and np.all(np.abs(equator[:, 1]) < 0.25)


@pytest.mark.parametrize("name,local", CASES)
def test_corridor_path_goes_through_the_opening(name, local):
    planner, space, start, goal = _planner(name, local, corridor_problem)
    states = _check(planner.solve(start, goal, 20.0), space, start, goal)
    crossing = states[np.abs(states[:, 0]) <= 0.05]
    assert len(crossing) and np.all(crossing[:, 1] > 1.6)
    assert np.allclose(states[:, 2], 0.0, atol=0.01)


def test_same_seed_same_path_and_json_summary():
    first, _, start, goal = _planner("rrtconnect", "auto", corridor_problem, seed=3)
    again, *_ = _planner("rrtconnect", "auto", corridor_problem, seed=3)
    a, b = first.solve(start, goal, 20.0), again.solve(start, goal, 20.0)
    np.testing.assert_array_equal(a.path, b.path)
    summary = json.loads(json.dumps(a.to_dict()))
    assert summary["solved"] and summary["waypoints"] == len(a.path) and "path" not in summary
    assert summary["planner"] == "rrtconnect" and summary["samples_drawn"] == a.samples_drawn > 0


def test_unsolvable_query_ends_at_the_time_limit_and_says_why():
    constraint, y, _, start, goal = corridor_problem()
    space = ConstrainedSpace(constraint, y, BoxChecker([([-0.05, -2.5, -0.5], [0.05, 2.5, 0.5])]))  # sealed
    result = PLANNERS.get("rrtconnect")(space, ProjectionSampler(space), seed=0).solve(start, goal, 0.3)
    assert not result.solved and result.path.shape == (0, 3) and result.length == 0.0
    assert 0.3 <= result.time_s < 1.5
    x = result.extras
    assert len(x["nodes"]) == 2 and min(x["nodes"]) > 1 and x["rejected"]["collision"] > 0
    assert x["sampler"]["accepted"] > 0 and x["evaluations"] > 0 and x["collision_checks"] > 0
    why = result.why()
    assert why.startswith("not solved in 0.3") and f"trees of {x['nodes'][0]} and {x['nodes'][1]} nodes" in why
    assert f"collision {x['rejected']['collision']}" in why and f"{result.samples_drawn} samples drawn" in why


class FailingSampler(ProjectionSampler):
    def candidates(self, count):
        return np.full((count, 3), 3.0)  # outside the limits: never valid


def test_a_sampler_that_gives_up_ends_the_query_with_its_reason():
    constraint, y, checker, start, goal = corridor_problem()
    space = ConstrainedSpace(constraint, y, checker)
    result = PLANNERS.get("rrtconnect")(space, FailingSampler(space, batch=8, max_batches=3), seed=0).solve(
        start, goal, 5.0)
    assert not result.solved and result.time_s < 1.0
    assert "found no valid configuration in 3 batches of 8" in result.extras["failure"]
    assert "the sampler failed: FailingSampler found no valid configuration" in result.why()


@pytest.mark.slow
def test_the_default_planner_solves_an_arm_with_full_turn_joints():
    """xarm7 (four joints with ±2π limits), the tool pointing down on the plane x = 0.3, no
    obstacles: projected samples almost never lie within range of a tree, so straight extensions
    through stepping stones never start (and say so); the default local planner walks there."""
    robot = Robot.load("xarm7")
    constraint = ConstraintSet([OrientationConstraint(robot, "link_eef", (0, 0, 1), (0, 0, -1)),
                                PlaneConstraint(robot, "link_eef", [[1, 0, 0]], [[0.3], [0.4]])])
    space = ConstrainedSpace(constraint, [0.3])
    rng = np.random.default_rng(1)
    seeds = project(constraint, robot.sample_uniform(8, rng), space.y).q
    start = seeds[space.valid(seeds)][0]
    goal = project(constraint, start + rng.normal(0, 1.0, 7), space.y).q[0]
    result = PLANNERS.get("rrtconnect")(space, ProjectionSampler(space, seed=0), seed=0).solve(start, goal, 10.0)
    _check(result, space, start, goal)
    assert result.extras["local"] == "auto" and result.length > 1.0
    stuck = PLANNERS.get("rrtconnect")(space, ProjectionSampler(space, seed=0), local="interpolate", seed=0,
                                   settings=RRTConnectSettings(pool=256)).solve(start, goal, 3.0)
    assert not stuck.solved and stuck.extras["rejected"]["range"] > 0
    assert "refused extensions: no sample within range" in stuck.why()


@pytest.mark.slow
@pytest.mark.parametrize("name", ["rrtconnect", "sbl"])
def test_coarse_checks_missing_a_thin_obstacle_are_caught_by_the_dense_validation(name):
    """At resolution 0.5 the straight checks step over a 2 cm slab; the final 0.005 check must
    refuse such paths (the offending edge is cut and the search goes on)."""
    constraint, y, _, start, goal = corridor_problem()
    space = ConstrainedSpace(constraint, y, BoxChecker([([-0.01, -2.5, -0.5], [0.01, 1.9, 0.5])]))
    cls = PLANNERS.get(name)
    planner = cls(space, ProjectionSampler(space, seed=0), seed=0,
                  settings=cls.settings_type(range=1.0, resolution=0.5))
    result = planner.solve(start, goal, 20.0)
    assert result.extras["rejected_paths"] > 0
    _check(result, space, start, goal)


def test_sbl_checks_edges_only_on_candidate_paths():
    """The corridor's wall cuts many of the unchecked edges that join the trees: those fail when a
    candidate path crosses them, edges off the candidate paths are never checked (here over 40 %
    of them), and the same seed gives the same path."""
    planner, space, start, goal = _planner("sbl", "interpolate", corridor_problem, seed=1)
    result = planner.solve(start, goal, 20.0)
    _check(result, space, start, goal)
    lazy = result.extras["lazy"]
    assert 0 < lazy["edges_removed"] < lazy["edges_checked"] < 0.6 * sum(result.extras["nodes"])
    again, *_ = _planner("sbl", "interpolate", corridor_problem, seed=1)
    np.testing.assert_array_equal(again.solve(start, goal, 20.0).path, result.path)
    with pytest.raises(ManifoldgenError, match="SBL needs cells > 0, dimensions >= 0 and bridge >= 0, got 0, 0, 0.6"):
        _planner("sbl", "auto", corridor_problem, cells=0)


def test_sbl_moves_the_nodes_beyond_a_failed_edge_to_the_other_tree():
    """Start tree start -> a -> b -> d, edge a -> b through the wall; goal tree goal -> c; candidate
    path bridged at b - c. The failed edge goes, and b and d (joined to the goal through the bridge)
    move to the goal tree as c -> b -> d, unchecked edges staying unchecked."""
    planner, space, start, goal = _planner("sbl", "interpolate", corridor_problem)
    planner._plant(start, goal, np.eye(2, 3), np.ones(2))
    a, b, c, d = (np.array(p) for p in ([-0.5, 0.0, 0.0], [0.5, 0.0, 0.0], [0.7, 0.2, 0.0], [0.5, 0.5, 0.0]))
    first, second = planner.trees
    ia, ib, id_ = first.add(0, a[None]), first.add(1, b[None]), first.add(2, d[None])
    ic = second.add(0, c[None])
    for k, i in ((0, ia), (0, ib), (0, id_), (1, ic)):
        planner._grids[k].add(i)
    assert planner._check(0, ia) and not planner._check(0, ib)
    planner._cut(0, ib, (ib, ic), None)
    assert not np.isfinite(first.q[[ib, id_], 0]).any() and np.allclose(first.q[ia], a)
    assert np.allclose(second.q[second.size - 2:second.size], [b, d])
    assert list(second.parent[second.size - 2:second.size]) == [ic, second.size - 2]
    assert planner._via[1].keys().isdisjoint({second.size - 2, second.size - 1}) and ia in planner._via[0]
    assert sorted(n for cell in planner._grids[1].cells.values() for n in cell) == [0, ic, ic + 1, ic + 2]
    assert sorted(n for cell in planner._grids[0].cells.values() for n in cell) == [0, ia]
    assert planner._extras()["lazy"] == {"edges_checked": 2, "edges_removed": 1}


def test_shortcut_keeps_the_constraint_and_shortens():
    """Shortcuts (the planners' ``shortcut`` setting, ``--smooth``): the same ends, a path valid by the dense check,
    shorter than the path as found, then relaxed in a planner's shortening; 0 attempts (the default) keep the path
    as found."""
    planner, space, start, goal = _planner("rrt", "interpolate", corridor_problem, seed=1, shortcut=0)
    found = planner.solve(start, goal, 20.0)
    assert "shortcuts" not in found.extras
    short, kept = shortcut(found.path, planner.local, attempts=200)
    assert kept > 0 and np.allclose(short[0], start) and np.allclose(short[-1], goal)
    assert space.validate_path(short).valid
    assert np.linalg.norm(np.diff(short, axis=0), axis=1).sum() < found.length - 0.1
    planner, space, start, goal = _planner("rrt", "auto", corridor_problem, seed=1, shortcut=50)
    result = planner.solve(start, goal, 20.0)
    _check(result, space, start, goal)
    assert result.extras["shortcuts"] > 0 and result.length < result.extras["found_length"] - 0.1
    assert result.extras["relaxed"] > 0  # the planner's shortening ends with the relaxation


def test_informed_searches_keep_the_shortest_path_and_draw_only_inside_the_informed_set(monkeypatch):
    """``informed``: after the first (shortened) path, searches whose sampler keeps only the rows a shorter path could
    visit (|x - start| + |x - goal| below the best length so far) and which pool no stepping stones ahead, until one
    finds none; the path kept is the shortest of them, valid state by state, and the sampler draws from the whole
    manifold again after the query. A restricted sampler whose set holds too few of its rows gives up once it has
    drawn INFORMED_PROBE, in one line. Each search's budget is a multiple of the first search's wall time: here a
    generous one, so that the first informed search finds its shorter path on a slow moment too (at twice, it once
    found none); whether the second finds one still depends on the machine."""
    import manifoldgen.planning.base as base
    from manifoldgen.sampling import INFORMED_PROBE
    monkeypatch.setattr(base, "INFORMED_BUDGET", 20.0)
    planner, space, start, goal = _planner("rrt", "auto", corridor_problem, seed=0, shortcut=50, informed=2)
    sampler, given = planner.sampler, []  # per restricted batch: the sum of distances to the ends, minus the length
    real = sampler._informed_rows

    def spy(q):
        kept = real(q)
        if sampler.informed is not None:
            s, g, length = sampler.informed
            given.append(np.linalg.norm(kept - s, axis=1) + np.linalg.norm(kept - g, axis=1) - length)
        return kept

    sampler._informed_rows = spy
    pools, pool_rows = [], planner.pool_rows  # (restricted?, rows pooled ahead) at each search's start

    def pooled():
        rows = pool_rows()
        pools.append((sampler.informed is not None, rows[0]))
        return rows

    planner.pool_rows = pooled
    result = planner.solve(start, goal, 20.0)
    _check(result, space, start, goal)
    assert pools[0] == (False, planner.settings.pool) and pools[1:] and all(p == (True, 0) for p in pools[1:])
    lengths = result.extras["informed"]  # the first path's, then each search's (None: none found in its budget)
    assert len(lengths) == 3 and lengths[1] is not None and lengths[1] < lengths[0]  # the first found a shorter path
    assert np.isclose(result.length, min(length for length in lengths if length is not None))  # the shortest kept
    rows = np.concatenate(given)
    assert len(rows) > 0 and (rows < 0).all()  # rows were drawn, every one inside the set
    assert sampler.informed is None
    sampler.restrict(start, goal, 0.5 * np.linalg.norm(goal - start))  # no state is that close to both ends
    with pytest.raises(ManifoldgenError, match=r"0 of its \d+ rows lay inside the informed set .* too few to search on"):
        sampler.raw_many(1)
    assert INFORMED_PROBE <= sampler._informed_counts[0] < INFORMED_PROBE + 2 * sampler.batch  # it stopped early


def test_relaxation_pulls_a_path_taut_on_the_manifold():
    """Relaxation (after the shortcuts): waypoints pulled toward their neighbours' midpoints and projected back; the
    same ends and waypoint count or fewer, a path valid by the dense check, shorter than the path as found, and a
    second pass gains less than the first (it converges)."""
    planner, space, start, goal = _planner("rrt", "auto", corridor_problem, seed=1, shortcut=0)
    found = planner.solve(start, goal, 20.0)
    taut, moves = relax(found.path, planner.local)
    assert moves > 0 and len(taut) <= len(found.path)
    np.testing.assert_array_equal(taut[[0, -1]], found.path[[0, -1]])
    assert space.validate_path(taut).valid
    length = np.linalg.norm(np.diff(taut, axis=0), axis=1).sum()
    assert length < found.length - 0.1
    again, _ = relax(taut, planner.local)
    assert found.length - length > length - np.linalg.norm(np.diff(again, axis=0), axis=1).sum() >= 0


def test_a_relaxed_path_that_fails_the_whole_check_is_not_kept():
    """The relaxation checks the motions through each probe only; the whole path is checked at the end, and when
    that check fails the path comes back as it was, with no moves counted."""
    from types import SimpleNamespace
    planner, space, start, goal = _planner("rrt", "auto", corridor_problem, seed=1, shortcut=0)
    found = planner.solve(start, goal, 20.0)

    class ProbesOnly:  # the space, but a path longer than a probe's three rows fails its check
        constraint = space.constraint

        def project(self, q, **options):
            return space.project(q, **options)

        def validate_path(self, path):
            report = space.validate_path(path)
            return report if len(path) == 3 else SimpleNamespace(valid=False)

    local = type(planner.local)(ProbesOnly())
    same, moves = relax(found.path, local)
    assert moves == 0 and local.projections > 0
    np.testing.assert_array_equal(same, found.path)


def test_reuse_routes_later_queries_through_the_paths_found():
    """``reuse``: a planner keeps its paths as a roadmap; a later query whose ends join it takes a route made of
    checked segments (valid state by state, the right ends, no search), one that cannot join it is planned."""
    planner, space, start, goal = _planner("rrt", "auto", corridor_problem, seed=1, reuse=True)
    first = planner.solve(start, goal, 20.0)
    _check(first, space, start, goal)
    assert first.extras["roadmap"]["routed"] is False and first.extras["roadmap"]["nodes"] == len(first.path)
    near_start, near_goal = start + [0.0, 0.05, 0.0], goal + [0.0, -0.05, 0.0]  # on the plane, beside the ends
    again = planner.solve(near_start, near_goal, 20.0)
    _check(again, space, near_start, near_goal)
    assert again.extras["roadmap"]["routed"] is True and again.iterations == 0 and again.samples_drawn == 0
    assert again.extras["roadmap"]["nodes"] == len(first.path) + 2  # the ends stay, joined to the roadmap
    far = np.array([-1.0, -1.9, 0.0])  # beyond reach of every node: planned, then kept
    third = planner.solve(far, goal, 20.0)
    _check(third, space, far, goal)
    assert third.extras["roadmap"]["routed"] is False and third.iterations > 0
    assert third.extras["roadmap"]["nodes"] == len(first.path) + 2 + len(third.path)


def test_a_roadmap_made_from_samples_answers_queries_without_a_search():
    """``Roadmap.of_samples``: a PRM's roadmap built before any query from a sampler's valid states; every edge it
    keeps passes the dense check, and a query whose ends join it is routed (no search) along checked segments."""
    planner, space, start, goal = _planner("rrt", "auto", corridor_problem, seed=1, reuse=True)
    rows = planner.sampler.sample_many(400)
    samples = rows[space.valid(rows)]
    planner.roadmap_of(samples)
    roadmap = planner.roadmap
    assert len(roadmap) == len(samples) > 300 and roadmap.edge_count() > len(samples)
    pairs, lengths = roadmap.edge_array()
    assert all(space.validate_path(samples[pair]).valid for pair in pairs[::10])
    assert np.allclose(np.linalg.norm(samples[pairs[:, 0]] - samples[pairs[:, 1]], axis=1), lengths)
    result = planner.solve(start, goal, 20.0)
    _check(result, space, start, goal)
    assert result.extras["roadmap"]["routed"] is True and result.iterations == 0 and result.samples_drawn == 0
    cold, *_ = _planner("rrt", "auto", corridor_problem, seed=1)
    with pytest.raises(ManifoldgenError, match="a roadmap is searched only with reuse on"):
        cold.roadmap_of(samples)


def test_a_route_found_past_the_time_limit_is_no_answer():
    """A route through the roadmap counts against the query's time limit: one checked past it is refused with the
    reason, and nothing else is tried."""
    planner, space, start, goal = _planner("rrt", "auto", corridor_problem, seed=1, reuse=True)
    planner.solve(start, goal, 20.0)
    route = planner.roadmap.route
    planner.roadmap.route = lambda a, b: (time.sleep(0.003), route(a, b))[1]  # a route checked slowly
    late = planner.solve(start, goal, 0.001)
    assert not late.solved and late.iterations == 0 and late.time_s > 0.001
    assert late.extras["failure"] == "the time limit (0.001 s) passed while the roadmap's route was checked"
    planner.roadmap.route = route
    assert planner.solve(start, goal, 20.0).extras["roadmap"]["routed"] is True


@pytest.mark.slow
def test_pg_and_cbirrt_solve_the_wall_scene(panda_task):
    scene = get_scene(panda_task, "wall")
    space = ConstrainedSpace(panda_task.constraint, scene.condition, scene.checker(panda_task.robot))
    data = collect(panda_task, 10_000, seed=2, conditions=[scene.condition], progress=False)
    pg = PLANNERS.get("rrtconnect")(space, DatasetSampler(space, data.q, data.y), seed=0)
    cbirrt = PLANNERS.get("cbirrt")(space, UniformSampler(space), seed=0)
    for planner in (pg, cbirrt):
        result = planner.solve(scene.start, scene.goal, 30.0)
        _check(result, space, scene.start, scene.goal)
    assert result.projections > 0 and result.extras["local"] == "project"


def test_bad_queries_are_refused_with_the_reason():
    constraint, y, checker, start, goal = corridor_problem()
    space = ConstrainedSpace(constraint, y, checker)
    planner = PLANNERS.get("rrt")(space, ProjectionSampler(space), seed=0)
    with pytest.raises(ManifoldgenError, match="time limit must be from 0.001 to 86400 seconds, got 0.0"):
        planner.solve(start, goal, 0.0)
    with pytest.raises(ManifoldgenError, match="time limit must be from 0.001 to 86400 seconds, got 10000000000.0"):
        planner.solve(start, goal, 1e10)  # the clock's arithmetic would overflow: "not solved in 0.000 s"
    with pytest.raises(ManifoldgenError, match=r"start configuration violates the constraint: .* 30.00 times"):
        planner.solve(start + [0, 0, 0.3], goal, 1.0)
    with pytest.raises(ManifoldgenError, match="goal configuration is in collision: point with box0"):
        planner.solve(start, np.zeros(3), 1.0)
    with pytest.raises(ManifoldgenError, match="rrt takes RRTSettings, got RRTConnectSettings"):
        PLANNERS.get("rrt")(space, ProjectionSampler(space), settings=RRTConnectSettings())
    with pytest.raises(ManifoldgenError, match="goal_bias"):
        PLANNERS.get("rrt")(space, ProjectionSampler(space), settings=RRTSettings(goal_bias=2))
    with pytest.raises(ManifoldgenError, match="rrtconnect needs a sampler"):
        PLANNERS.get("rrtconnect")(space, None)
    with pytest.raises(ManifoldgenError, match=r"the sampler serves condition \[0.5\], the planner \[0.0\]"):
        PLANNERS.get("rrtconnect")(space, ProjectionSampler(ConstrainedSpace(constraint, [0.5])))
    with pytest.raises(ManifoldgenError, match="unknown local planner 'straight'; known: auto, interpolate, project"):
        PLANNERS.get("rrtconnect")(space, ProjectionSampler(space), local="straight")


@pytest.mark.slow
def test_cbirrt_without_a_sampler_draws_uniform_targets():
    constraint, y, checker, start, goal = corridor_problem()
    space = ConstrainedSpace(constraint, y, checker)
    result = PLANNERS.get("cbirrt")(space, None, seed=0).solve(start, goal, 20.0)
    _check(result, space, start, goal)


class _AwayFromGoal(ProjectionSampler):
    """Projection samples none of which lies within 0.7 of the sphere's north pole (the goal): a sampler that
    leaves the goal's neighbourhood empty, as the learned samplers leave a tray goal's."""

    def candidates(self, count):
        q = super().candidates(count)
        return q[np.linalg.norm(q - [0.0, 0.0, 1.0], axis=1) > 0.7]


@pytest.mark.parametrize("name", ["rrt", "kpiece", "prm"])
def test_single_query_planners_reach_a_goal_no_sample_lies_near(name):
    """RRT and KPIECE step only through samples, so no node ever comes within range of a goal with no sample
    near it; their goal-biased growth walks out from the goal for its targets (each state walked valid, on the
    sphere, within goal_radius of the goal, joining the pool). PRM expands the goal's component instead."""
    constraint, y, checker, start, goal = sphere_problem()
    space = ConstrainedSpace(constraint, y, checker)
    cls = PLANNERS.get(name)
    planner = cls(space, _AwayFromGoal(space, seed=3), seed=3, settings=cls.settings_type(range=0.3))
    _check(planner.solve(start, goal, 20.0), space, start, goal)
    if name == "prm":
        return
    planner.trees = [Tree(start)]
    planner._start_pool(planner.trees, np.inf)
    before = planner.pool.head
    target = planner._goal_target(goal, 0.5)
    walked = planner.pool.q[before:planner.pool.head]
    assert len(walked) and np.array_equal(walked[-1], target)
    # walks end their last step
    assert np.linalg.norm(target - goal) <= 0.5 + planner.settings.step and space.valid(walked).all()
    assert np.abs(np.linalg.norm(walked, axis=1) - 1.0).max() < 0.01
