"""The C++ OMPL baseline (a benchmark extra): its constraint and collision checker equal ours, and its
paths pass our dense check. Tests that need the built program skip, saying why, without it."""

import numpy as np
import pytest

from manifoldgen import core_terms
from manifoldgen.constraints import PlaneConstraint
from manifoldgen.errors import ManifoldgenError
from manifoldgen.ompl_settings import OmplSettings
from manifoldgen.space import ConstrainedSpace, densify

ompl_native = pytest.importorskip("manifoldgen.ompl_native")


def _built() -> bool:
    try:
        ompl_native.native_binary()
        return True
    except ManifoldgenError:
        return False


needs_binary = pytest.mark.skipif(not _built(), reason="the C++ OMPL baseline is not built "
                                  "(apt-get install libompl-dev; benchmarks/ompl_native/build.sh)")


@pytest.fixture(scope="module")
def maze():
    from manifoldgen.scene import get_scene
    from manifoldgen.tasks import get_task
    task = get_task("pose", "panda")
    scene = get_scene(task, "maze")
    return task, scene, ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))


@pytest.fixture(scope="module")
def tray():
    from manifoldgen.scene import get_scene
    from manifoldgen.tasks import get_task
    task = get_task("dualarm", "pr2")
    scene = get_scene(task, "tray-over")
    return task, scene, ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))


@pytest.mark.slow
@needs_binary
@pytest.mark.parametrize("problem", ["maze", "tray"])
def test_residuals_jacobians_and_collisions_equal_ours(problem, request):
    """The pose task, and the dual-arm closed chain + tray rotation with the held tray."""
    task, scene, space = request.getfixturevalue(problem)
    q = task.robot.sample_uniform(120, np.random.default_rng(3))
    q[:40] = space.project(q[:40]).q  # on the manifold too, where the planners live
    q[40:60] = densify(np.array([scene.start, scene.goal]), 0.05)[0][:20]  # near the obstacles
    F, J, free = ompl_native.evaluate(space, q)
    F_ours, J_ours = task.constraint.jacobian(q, np.broadcast_to(space.y, (len(q), len(space.y))))
    np.testing.assert_allclose(F, F_ours, atol=1e-8)
    np.testing.assert_allclose(J[:40], J_ours[:40], atol=1e-8)
    np.testing.assert_allclose(J, J_ours, atol=1e-6)  # off the manifold, log3 near pi loses digits
    ours = ~space.checker.in_collision(q)
    assert np.array_equal(free, ours) and 0 < ours.sum() < len(q)  # both verdicts occur


@needs_binary
def test_atlas_path_passes_our_dense_check_and_is_reproducible(maze):
    task, scene, space = maze
    planner = ompl_native.NativeOmplPlanner(space, ompl_space="atlas", seed=4)
    result = planner.solve(scene.start, scene.goal, 20.0)
    assert result.solved and result.extras["valid"]
    path = result.path
    np.testing.assert_allclose(path[0], scene.start) and np.testing.assert_allclose(path[-1], scene.goal)
    states = densify(path, space.settings.resolution)[0]  # state by state, with our rule
    assert task.constraint.violation(states, space.y).max() <= 1.0
    assert task.robot.within_limits(states).all() and not space.checker.in_collision(states).any()
    ops = result.extras["native_ops"]
    assert ops["fk"] >= ops["jacobians"] > 0 and ops["collision_checks"] > 0 and result.extras["native_cpu_s"] > 0
    assert ops["samples"] > 0 and result.iterations >= 2  # OMPL's own samples; its tree's vertices
    again = ompl_native.NativeOmplPlanner(space, ompl_space="atlas", seed=4).solve(scene.start, scene.goal, 20.0)
    np.testing.assert_array_equal(again.path, path)
    # shortcut: OMPL's shortcutPath on the same accepted path, rechecked by our dense check, shorter
    short = ompl_native.NativeOmplPlanner(space, ompl_space="atlas", seed=4, settings=OmplSettings(shortcut=50)).solve(
        scene.start, scene.goal, 20.0)
    assert short.solved and short.extras["shortened"] and short.extras["found_length"] == pytest.approx(result.length)
    assert short.length < result.length and space.validate_path(short.path).valid
    np.testing.assert_allclose(short.path[[0, -1]], path[[0, -1]])


@needs_binary
def test_the_atlas_knobs_reach_ompl(maze):
    """OMPL's defaults written out give the default search, state for state; other atlas knobs give another
    search whose path still passes our dense check. A benchmark's ``ompl_KEY`` settings go to OMPL only."""
    task, scene, space = maze
    solve = lambda settings: ompl_native.NativeOmplPlanner(space, ompl_space="atlas", seed=4, settings=settings).solve(
        scene.start, scene.goal, 20.0)
    default = solve(OmplSettings())
    explicit = solve(OmplSettings(epsilon=0.05, rho=0.25, alpha=np.pi / 8, exploration=0.75, separated=True))
    np.testing.assert_array_equal(explicit.path, default.path)
    other = solve(OmplSettings(epsilon=0.1, separated=False))
    assert other.solved and space.validate_path(other.path).valid
    assert other.extras["native_ops"]["fk"] != default.extras["native_ops"]["fk"]
    chosen = OmplSettings.from_benchmark({"ompl_epsilon": 0.1, "ompl_lambda": 3.0, "range": 0.9, "shortcut": 5})
    assert (chosen.epsilon, chosen.lambda_, chosen.range, chosen.shortcut) == (0.1, 3.0, 0.6, 5)
    with pytest.raises(ManifoldgenError, match="invalid OMPL settings.*0 < alpha < pi/2"):
        OmplSettings(alpha=2.0).check()


def test_bad_input_is_refused_in_one_line(maze, monkeypatch, tmp_path):
    task, scene, space = maze
    monkeypatch.setenv(ompl_native.BINARY_ENV, str(tmp_path / "missing"))
    with pytest.raises(ManifoldgenError, match="not built.*build.sh"):
        ompl_native.NativeOmplPlanner(space)
    broken = tmp_path / "broken"
    broken.write_text("#!/bin/sh\necho 'ompl_native: cannot read problem file' >&2\nexit 1\n")
    broken.chmod(0o755)
    monkeypatch.setenv(ompl_native.BINARY_ENV, str(broken))
    with pytest.raises(ManifoldgenError, match="baseline failed: ompl_native: cannot read problem file; rebuild"):
        ompl_native.NativeOmplPlanner(space).solve(scene.start, scene.goal, 1.0)
    plane = PlaneConstraint(task.robot, "panda_hand_tcp", [[0, 0, 1]], [[0.3], [0.5]])
    monkeypatch.setattr(core_terms, "compiled_part", lambda part, y, robot: "its residual does not trace: a test")
    with pytest.raises(ManifoldgenError, match="cannot take this task .the compiled core has no .plane. constraint "
                                               "term .* does not compile .its residual does not trace: a test"):
        ompl_native.NativeOmplPlanner(ConstrainedSpace(plane, [0.4]))
    with pytest.raises(ManifoldgenError, match="unknown native OMPL space"):
        ompl_native.NativeOmplPlanner(space, ompl_space="curved")


@needs_binary
def test_the_sphere_broad_phase_changes_no_verdict_of_the_baseline(maze):
    """With our sphere models (the default; ``--set spheres=false`` turns them off) the C++ Atlas search is the
    same, seed for seed, with fewer coal checks: the spheres only spare coal where they touch nothing."""
    task, scene, space = maze
    plain = ompl_native.NativeOmplPlanner(space, ompl_space="atlas", seed=4, spheres=False).solve(
        scene.start, scene.goal, 20.0)
    spheres = ompl_native.NativeOmplPlanner(space, ompl_space="atlas", seed=4).solve(
        scene.start, scene.goal, 20.0)
    assert plain.solved and spheres.solved
    np.testing.assert_array_equal(spheres.path, plain.path)
    assert spheres.extras["sphere_checks"] > 0 and plain.extras["sphere_checks"] == 0
    assert spheres.extras["native_ops"]["collision_checks"] < plain.extras["native_ops"]["collision_checks"]


@needs_binary
def test_bench_charges_the_baseline_its_program_and_our_dense_check_not_the_harness():
    from manifoldgen.bench.planning import Experiment, Method, run_once
    record = run_once(Experiment("wall", time_limit=20.0), Method.parse("atlas-c++=ompl-native-atlas"), 0)
    extras = record["extras"]
    assert record["solved"] and extras["dense_cpu_s"] > 0 and record["harness_cpu_s"] >= 0
    assert record["cpu_s"] == pytest.approx(extras["native_cpu_s"] + extras["dense_cpu_s"])


@needs_binary
def test_a_compiled_python_constraint_runs_in_the_baseline(maze):
    """A user's Python constraint that compiles reaches C++ Atlas as the core's expression term: every waypoint
    of the path it returns satisfies the Python constraint, and the path passes the space's dense check."""
    task, scene, _ = maze
    plane = PlaneConstraint(task.robot, "panda_hand_tcp", [[0, 0, 1]], [[0.3], [0.5]])
    space = ConstrainedSpace(plane, [0.4])
    start, goal = (space.project(space.robot.sample_uniform(200, np.random.default_rng(s)), max_iters=50).q
                   for s in (1, 2))
    ok = [q for q in np.concatenate([start, goal]) if space.valid(q[None])[0]]
    result = ompl_native.NativeOmplPlanner(space, ompl_space="atlas", seed=0).solve(ok[0], ok[-1], 20.0)
    assert result.solved and space.validate_path(result.path).valid
    assert plane.satisfied(result.path, np.full((len(result.path), 1), 0.4)).all()
