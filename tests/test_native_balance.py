"""Whole-body tasks in the compiled core and the C++ OMPL baseline, against the Python reference: the floating
base (six Euler coordinates -> pinocchio's free flyer), balance (feet, base height, the CoM margin on pinocchio's
centre of mass), orientation (two rows and its hemisphere) and joint_linear terms; residuals, Jacobians,
inequalities, validity verdicts, projection, motion and path checks; native RRT-Connect paths rechecked state by
state (feet, CoM, limits, collisions)."""

import numpy as np
import pytest

from manifoldgen import core_extension, native
from manifoldgen.space import REASONS, ConstrainedSpace, densify
from manifoldgen.stability import path_stability

from certified_paths import compare_certified, manifold_polylines

pytest.importorskip("manifoldgen_core", reason="the compiled core is not built (scripts/setup.sh builds it)")

PROBLEMS = {"talos": ("balance", "talos", "reach"), "centauro": ("balance", "centauro", "reach"),
            "drinkcan": ("drinkcan", None, "drinkcan")}


@pytest.fixture(scope="module", params=list(PROBLEMS))
def problem(request):
    """(task, scene, space, core) of each whole-body problem."""
    from manifoldgen.scene import get_scene
    from manifoldgen.tasks import get_task
    name, robot, scene_name = PROBLEMS[request.param]
    task = get_task(name, robot)
    scene = get_scene(task, scene_name)
    space = ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))
    return task, scene, space, native.core_space(space)


def _states(task, scene, space, seed=3):
    """Uniform states (floating base anywhere in its bounds), states near the start projected onto the manifold,
    and states along the start-goal chord."""
    rng = np.random.default_rng(seed)
    uniform = task.robot.sample_uniform(60, rng)
    near = np.clip(scene.start + 0.1 * rng.standard_normal((40, space.n)), task.robot.lower, task.robot.upper)
    chord = densify(np.array([scene.start, scene.goal]), 0.02)[0][:40]
    return np.concatenate([space.project(near).q, chord, uniform])


def _codes(space, q, limit):
    """The Python rule's first failed test per row (collision included), as the core numbers them."""
    code, _ = space._failures(q, limit)
    free = code == 0
    code[free] = np.where(space.checker.in_collision(q[free]), 4, 0)
    return code


@pytest.mark.slow
def test_whole_body_tasks_are_built_in(problem):
    task, _, space, core = problem
    assert core_extension.unsupported(space) is None
    assert (core.n, core.m) == (space.n, task.constraint.m) and core.g > 0


def test_residuals_jacobians_inequalities_and_validity_equal_the_python_space(problem):
    task, scene, space, core = problem
    q = _states(task, scene, space)
    y = np.broadcast_to(space.y, (len(q), len(space.y)))
    F, J = core.jacobian(q)
    F_py, J_py = task.constraint.jacobian(q, y)
    np.testing.assert_allclose(F, F_py, atol=1e-9)
    np.testing.assert_allclose(J[:80], J_py[:80], atol=1e-9)  # on the manifold and along the chord
    np.testing.assert_allclose(J, J_py, atol=1e-7)  # off it, log3 near pi loses a few digits either way
    np.testing.assert_allclose(core.residual(q), F_py, atol=1e-9)
    np.testing.assert_allclose(core.inequality(q), task.constraint.inequality(q, y), atol=1e-9)
    for limit in (1.0, 0.95):
        ours = core.codes(q, np.full(len(q), limit), True, True)
        assert np.array_equal(ours, _codes(space, q, limit))
    assert {0, 2}.issubset(set(ours.tolist()))  # valid states and off-manifold ones both occur
    assert np.array_equal(native.NativeSpace(space, core).valid(q), space.valid(q))


def test_floating_base_maps_to_the_free_flyer_as_the_python_robot_does(problem):
    task, scene, space, core = problem
    robot = task.robot
    if not robot.floating_base:
        pytest.skip("fixed base")
    assert core_extension.active_coordinates(robot)[0] == (0, 0, 7)  # pinocchio's free flyer: position and quaternion
    rng = np.random.default_rng(1)
    q = np.clip(scene.start + 0.2 * rng.standard_normal((20, space.n)), robot.lower, robot.upper)
    # the Jacobian's base columns against central differences of the core's own residual (away from log3's pi)
    _, J = core.jacobian(q)
    h = 1e-6
    for i in range(6):
        step = np.zeros(space.n)
        step[i] = h
        numeric = (core.residual(q + step) - core.residual(q - step)) / (2 * h)
        np.testing.assert_allclose(J[:, :, i], numeric, atol=1e-6)


def test_projection_equals_the_python_algorithm(problem):
    task, scene, space, core = problem
    rng = np.random.default_rng(5)
    q = np.clip(scene.start + 0.1 * rng.standard_normal((30, space.n)), task.robot.lower, task.robot.upper)
    x, ok, iterations, residual = core.project(q, 1e-6, 50, 1e-6, 0.5)
    reference = space.project(q)
    ok = ok.astype(bool)
    assert ok.mean() > 0.5 and np.array_equal(ok, reference.converged)
    assert np.array_equal(iterations, reference.iterations)
    np.testing.assert_allclose(x[ok], reference.q[ok], atol=1e-8)
    assert np.all(space.violation(x[ok]) <= 1e-3) and task.robot.within_limits(x).all()


def test_motion_and_path_checks_equal_the_python_space(problem):
    task, scene, space, core = problem
    chord = densify(np.array([scene.start, scene.goal]), 0.05)[0]
    assert core.valid_prefix(chord, True) == space.valid_prefix(chord, True)
    assert (REASONS[core.stop - 1] if core.stop else None) == space.stop
    path = np.array([scene.start, scene.goal])
    valid, worst, first, reason, segment, states = core.validate_path(path)
    report = space.validate_path(path)
    assert valid == report.valid and segment == report.segment
    assert valid or first + 1 == report.states_checked


def test_the_com_margin_is_checked_on_pinocchios_centre_of_mass():
    """A state on the manifold but outside the support polygon is refused for its inequality (code 3), by the
    core as by the Python rule; pinocchio's centre of mass agrees with the robot's."""
    import pinocchio as pin

    from manifoldgen.tasks import get_task
    task = get_task("balance", "talos")
    robot, balance = task.robot, task.constraint
    space = ConstrainedSpace(balance, [0.98])
    core = native.core_space(space)
    q = robot.sample_uniform(200, np.random.default_rng(0))
    q = space.project(q).q
    q = q[space.violation(q) <= 1.0]
    data = robot.model.createData()
    com = np.array([pin.centerOfMass(robot.model, data, full) for full in robot.to_pinocchio(q)])
    np.testing.assert_allclose(com, robot.com(q), atol=1e-9)
    outside = balance.com_depth(q) < balance.margin
    assert outside.any() and (~outside).any()
    codes = core.codes(q, np.ones(len(q)), False, True)
    assert np.array_equal(codes == 3, outside) and np.all(codes[~outside] == 0)


def _plan(task, scene, sampler: str, seed: int, time_limit: float = 20.0):
    from manifoldgen.planning import RRTConnect, RRTConnectSettings
    from manifoldgen.specs import make_sampler
    space = ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))
    planner = RRTConnect(space, make_sampler(sampler, space, seed), seed=seed,
                         settings=RRTConnectSettings(pool=32, pool_batch=64))
    return space, planner.solve(scene.start, scene.goal, time_limit)


@pytest.mark.slow
def test_native_rrt_connect_balance_path_passes_the_python_check_state_by_state(problem):
    task, scene, space, core = problem
    space, result = _plan(task, scene, "project", seed=0)
    assert result.solved and result.extras["core"] == "native"
    path = result.path
    np.testing.assert_allclose(path[0], scene.start)
    np.testing.assert_allclose(path[-1], scene.goal)
    states = densify(path, space.settings.resolution)[0]
    y = np.broadcast_to(space.y, (len(states), len(space.y)))
    assert task.constraint.violation(states, space.y).max() <= 1.0
    assert np.all(task.constraint.inequality(states, y) <= 0)
    assert task.robot.within_limits(states).all() and not space.checker.in_collision(states).any()
    assert space.validate_path(path).valid
    if task.robot.floating_base:
        stability = path_stability(task.constraint, path)
        assert stability.stable and stability.max_foot_drift <= 0.01


def test_core_refuses_a_misplaced_free_flyer_and_a_degenerate_polygon(problem):
    import manifoldgen_core
    task, scene, space, core = problem
    with pytest.raises(ValueError, match="H >= 3"):
        core.add_term("com_polygon", {"normals": [[0.0, 0.0], [0.0, 0.0]], "bounds": [0.0, 0.0]})
    if not task.robot.floating_base:
        return
    active = core_extension.active_coordinates(task.robot)
    with pytest.raises(RuntimeError, match="free flyer"):
        import tempfile
        from pathlib import Path
        with tempfile.TemporaryDirectory() as folder:
            model, geometry = core_extension.write_models(space, Path(folder))
            manifoldgen_core.Space(str(model), str(geometry), task.robot.reference, active[1:] + active[:1],
                                   task.robot.lower, task.robot.upper, 0.05, 0.005)


def _ompl_built() -> bool:
    from manifoldgen.errors import ManifoldgenError
    from manifoldgen.ompl_native import native_binary
    try:
        native_binary()
        return True
    except ManifoldgenError:
        return False


@pytest.mark.skipif(not _ompl_built(), reason="the C++ OMPL baseline is not built "
                    "(apt-get install libompl-dev; benchmarks/ompl_native/build.sh)")
def test_cpp_ompl_baseline_takes_whole_body_tasks(problem):
    """The C++ OMPL baseline's residuals and Jacobians equal ours on the floating base and the whole-body terms,
    and its Atlas path keeps the equalities, the inequalities (CoM margin, hemisphere; through state validity),
    the limits and the collisions at every state of our dense check."""
    from manifoldgen.ompl_native import NativeOmplPlanner, evaluate
    task, scene, space, core = problem
    q = _states(task, scene, space)[:80]
    F, J, free = evaluate(space, q)
    y = np.broadcast_to(space.y, (len(q), len(space.y)))
    F_py, J_py = task.constraint.jacobian(q, y)
    np.testing.assert_allclose(F, F_py, atol=1e-9)
    np.testing.assert_allclose(J, J_py, atol=1e-9)
    assert np.array_equal(free, ~space.checker.in_collision(q))
    if task.robot.name == "centauro" and task.robot.floating_base:
        return  # C++ Atlas does not solve centauro's reach within 30 s (README, "Whole-body against C++ OMPL")
    result = NativeOmplPlanner(space, ompl_space="atlas", seed=0).solve(scene.start, scene.goal, 20.0)
    assert result.solved and result.extras["native_ops"]["inequalities"] > 0
    states = densify(result.path, space.settings.resolution)[0]
    y = np.broadcast_to(space.y, (len(states), len(space.y)))
    assert task.constraint.violation(states, space.y).max() <= 1.0
    assert np.all(task.constraint.inequality(states, y) <= 0)
    assert task.robot.within_limits(states).all() and not space.checker.in_collision(states).any()


@pytest.mark.slow
def test_certified_constraints_give_the_exact_report(problem):
    """validate_path(certify=True) on the whole-body terms (feet poses, base height, the CoM polygon; drinkcan's
    orientation and hemisphere): the state-by-state report (see certified_paths), for fewer evaluations."""
    task, scene, space, core = problem
    reasons, evaluations = compare_certified(core, manifold_polylines(space, core, scene.start, 0.4, 7))
    assert 0 in reasons and reasons & {2, 3}  # valid paths, and constraint or inequality failures between waypoints
    assert evaluations[True] < evaluations[False]
