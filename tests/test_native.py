"""The compiled core (manifoldgen_core) against the Python reference: residuals, Jacobians, the validity
rule, projection, motion and path checks, RRT-Connect paths rechecked state by state, the fallback for
Python constraints, and the sphere-model hook."""

import numpy as np
import pytest

from manifoldgen import core_extension, core_terms, native
from manifoldgen.errors import ManifoldgenError
from manifoldgen.planning import RRTConnectSettings
from manifoldgen.sampling import FIRST_ROWS
from manifoldgen.space import REASONS, ConstrainedSpace, densify

pytest.importorskip("manifoldgen_core", reason="the compiled core is not built (scripts/setup.sh builds it)")


def _problem(task, scene_name: str):
    """(task, scene, its constrained space, the core built from it)."""
    from manifoldgen.scene import get_scene
    scene = get_scene(task, scene_name)
    space = ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))
    return task, scene, space, native.core_space(space)


@pytest.fixture(scope="module")
def maze(panda_task):
    return _problem(panda_task, "maze")


@pytest.fixture(scope="module")
def dualarm():
    from manifoldgen.tasks import get_task
    return _problem(get_task("dualarm", "baxter"), "tray-over")


@pytest.fixture(scope="module")
def sphere():
    from manifoldgen.tasks import get_task
    return _problem(get_task("sphere", "point"), "sphere")


def _states(task, scene, space, seed=3):
    """Random states, states projected onto the manifold, and states along the start-goal chord."""
    q = task.robot.sample_uniform(150, np.random.default_rng(seed))
    q[:60] = space.project(q[:60]).q
    chord = densify(np.array([scene.start, scene.goal]), 0.02)[0]
    return np.concatenate([q, chord[:60]])


def _codes(space, q, limit):
    """The Python rule's first failed test per row (collision included), as the core numbers them."""
    code, _ = space._failures(q, limit)
    free = code == 0
    code[free] = np.where(space.checker.in_collision(q[free]), 4, 0)
    return code


@pytest.mark.parametrize("problem", ["maze", "dualarm", "sphere"])
def test_residuals_jacobians_and_validity_equal_the_python_space(problem, request):
    task, scene, space, core = request.getfixturevalue(problem)
    q = _states(task, scene, space)
    y = np.broadcast_to(space.y, (len(q), len(space.y)))
    F, J = core.jacobian(q)
    F_py, J_py = task.constraint.jacobian(q, y)
    on = slice(0, 60)  # on the manifold: where the planners live
    np.testing.assert_allclose(F, F_py, atol=1e-9)
    np.testing.assert_allclose(J[on], J_py[on], atol=1e-9)
    np.testing.assert_allclose(J, J_py, atol=1e-7)  # off it, log3 near pi loses a few digits either way
    np.testing.assert_allclose(core.residual(q), F_py, atol=1e-9)
    np.testing.assert_allclose(core.violation(q), space.violation(q), atol=1e-9)
    for limit in (1.0, 0.95):
        ours = core.codes(q, np.full(len(q), limit), True, True)
        expected = _codes(space, q, limit)
        assert np.array_equal(ours, expected)
        assert len(set(expected.tolist()) & {0, 4}) == 2  # valid and colliding states both occur
    assert np.array_equal(native.NativeSpace(space, core).valid(q), space.valid(q))


def test_projection_equals_the_python_algorithm(maze):
    task, scene, space, core = maze
    q = task.robot.sample_uniform(60, np.random.default_rng(5))
    x, ok, iterations, residual = core.project(q, 1e-6, 50, 1e-6, 0.5)
    reference = space.project(q)
    ok = ok.astype(bool)
    assert ok.mean() > 0.5 and np.array_equal(ok, reference.converged)
    assert np.array_equal(iterations, reference.iterations)
    np.testing.assert_allclose(x[ok], reference.q[ok], atol=1e-8)
    assert np.all(residual[ok] <= 1e-6)
    assert np.all(space.violation(x[ok]) <= 1e-4) and task.robot.within_limits(x).all()
    short = native.NativeSpace(space, core).project(q, max_iters=2)  # the sampler's refinement
    np.testing.assert_allclose(short.q, space.project(q, max_iters=2).q, atol=1e-8)


def test_motion_and_path_checks_equal_the_python_space(maze):
    task, scene, space, core = maze
    chord = densify(np.array([scene.start, scene.goal]), 0.05)[0]
    assert core.valid_prefix(chord, True) == space.valid_prefix(chord, True) < len(chord)
    assert REASONS[core.stop - 1] == space.stop
    on = space.project(task.robot.sample_uniform(40, np.random.default_rng(2))).q
    for k in range(0, 40, 2):
        states = densify(on[k:k + 2], 0.05)[0]
        assert core.valid_prefix(states, True) == space.valid_prefix(states, True)
    path = np.array([scene.start, scene.goal])
    valid, worst, first, reason, segment, states = core.validate_path(path)
    report = space.validate_path(path)
    assert not valid and not report.valid and segment == report.segment == 0 and first + 1 == report.states_checked
    assert report.reason.startswith(f"segment 0: {'is in collision' if reason == 4 else 'violates'}")


@pytest.fixture(scope="module")
def wall(panda_task):
    from manifoldgen.scene import get_scene
    return get_scene(panda_task, "wall")


def _planner(task, scene, seed, core="native", sampler="cvae", spheres=False):
    from manifoldgen.models import pretrained_model_dir
    from manifoldgen.planning import RRTConnect, RRTConnectSettings
    from manifoldgen.specs import make_sampler
    space = ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))
    spec = f"cvae:{pretrained_model_dir()}" if sampler == "cvae" else sampler
    return space, RRTConnect(space, make_sampler(spec, space, seed), seed=seed,
                             settings=RRTConnectSettings(core=core, spheres=spheres))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_native_rrt_connect_paths_pass_the_python_check_state_by_state(panda_task, wall, seed):
    space, planner = _planner(panda_task, wall, seed)
    before = space.counts()
    result = planner.solve(wall.start, wall.goal, 20.0)
    after = space.counts()
    assert result.solved and result.extras["core"] == "native"
    path = result.path
    np.testing.assert_allclose(path[0], wall.start) and np.testing.assert_allclose(path[-1], wall.goal)
    states = densify(path, space.settings.resolution)[0]
    assert panda_task.constraint.violation(states, space.y).max() <= 1.0
    assert panda_task.robot.within_limits(states).all() and not space.checker.in_collision(states).any()
    assert space.validate_path(path).valid
    # the same counters as a Python search, booked on the space
    checks = after["collision_checks"] - before["collision_checks"]
    assert 0 < result.extras["collision_checks"] == checks - 2  # the start and goal are checked before the count
    assert result.extras["evaluations"] > 0 and after["jacobians"] > before["jacobians"]
    assert sum(result.extras["nodes"]) >= 2 and result.samples_drawn > 0 and result.iterations >= 0


def test_a_sampler_that_gives_up_ends_the_native_query_with_its_reason(panda_task, wall):
    space, planner = _planner(panda_task, wall, 0)
    planner.sampler.raw = lambda count: np.zeros((0, space.n))  # the model's rows, before refinement
    planner.sampler.max_batches = 3
    result = planner.solve(wall.start, wall.goal, 5.0)
    assert not result.solved and "found no valid configuration in 3 batches" in result.extras["failure"]
    assert planner.sampler.space is space  # the sampler gets its own space back


def test_core_choice_and_python_constraints_through_callbacks(panda_task, wall):
    from manifoldgen.constraints import PlaneConstraint
    from manifoldgen.planning import RRTConnect, RRTConnectSettings
    from manifoldgen.specs import make_sampler
    plane = PlaneConstraint(panda_task.robot, "panda_hand", normals=(0, 0, 1), values=[[0.5]])
    space = ConstrainedSpace(plane, [0.5])
    assert core_extension.unsupported(space) is None  # a Python constraint runs in the core: compiled, else callbacks
    assert core_terms.constraint_terms(space)[0]["type"] == "expression"  # the C++ OMPL baseline gets it compiled
    auto = RRTConnect(space, make_sampler("project", space, 0))
    assert auto.core is not None and not auto.core.batched and auto._extras()["core"] == "native"
    assert auto._extras()["compiled"] == ["plane"] and "compile_fallback" not in auto._extras()
    callbacks = RRTConnect(space, make_sampler("project", space, 0), settings=RRTConnectSettings(compile=False))
    assert callbacks.core.batched and callbacks._extras()["compile_fallback"] == "plane: compilation is off"
    with pytest.raises(ManifoldgenError, match="unknown core"):
        RRTConnectSettings(core="gpu").check()
    _, python = _planner(panda_task, wall, 0, core="python")
    assert python.core is None and python._extras() == {"core": "python"}


def _bounding_spheres(space, names=("panda_link7", "panda_hand", "panda_leftfinger", "panda_rightfinger")):
    """One sphere around the bounding box of each robot geometry on the ``names`` links (conservative: it covers
    the geometry); the other geometries stay exact."""
    joint, center, radius, geometry = [], [], [], []
    robot_geoms = len(space.robot.collision_model.geometryObjects)
    for i, g in enumerate(space.checker.geom.geometryObjects[:robot_geoms]):
        if space.robot.model.frames[g.parentFrame].name not in names:
            continue
        g.geometry.computeLocalAABB()
        joint.append(g.parentJoint)
        center.append(g.placement.act(np.asarray(g.geometry.aabb_center)))
        radius.append(g.geometry.aabb_radius)
        geometry.append(i)
    return {"joint": joint, "center": np.array(center), "radius": np.array(radius), "geometry": geometry}


def test_sphere_models_are_conservative_and_plan_valid_paths(panda_task, wall):
    space, planner = _planner(panda_task, wall, 0)
    report = native.set_spheres(planner.core, _bounding_spheres(space))
    assert "sphere-primitive" in report and planner.core.has_spheres
    q = _states(panda_task, wall, space, seed=7)
    spheres = planner.core.codes(q, np.full(len(q), np.inf), True, False)
    exact = planner.core.codes(q, np.full(len(q), np.inf), True, True)
    assert not np.any((spheres == 0) & (exact == 4))  # sphere-free implies mesh-free
    assert np.any((spheres == 4) & (exact == 0)) and np.any(spheres == 0)  # conservative, not all blocked
    result = planner.solve(wall.start, wall.goal, 20.0)
    assert result.solved and result.extras["sphere_checks"] > 0
    states = densify(result.path, space.settings.resolution)[0]
    assert not space.checker.in_collision(states).any() and space.validate_path(result.path).valid
    # a broad phase, not an approximation: the same search and path as coal alone, with fewer coal checks
    _, plain = _planner(panda_task, wall, 0)
    alone = plain.solve(wall.start, wall.goal, 20.0)
    np.testing.assert_array_equal(alone.path, result.path)
    assert result.extras["collision_checks"] < alone.extras["collision_checks"]
    with pytest.raises(ManifoldgenError, match="bad sphere model"):
        native.set_spheres(planner.core, {"joint": [1], "center": np.zeros((2, 3)), "radius": [0.1], "geometry": [0]})


def test_the_spheres_setting_fits_the_robot_and_keeps_the_search(panda_task, wall):
    """``spheres=True`` (the default): the robot's sphere models (manifoldgen.spheres) as the broad phase of every
    check."""
    assert RRTConnectSettings().spheres
    _, with_spheres = _planner(panda_task, wall, 1, spheres=True)
    _, plain = _planner(panda_task, wall, 1)
    assert with_spheres.core.has_spheres and not plain.core.has_spheres
    a, b = (p.solve(wall.start, wall.goal, 20.0) for p in (with_spheres, plain))
    assert a.solved and a.extras["sphere_checks"] > 0
    np.testing.assert_array_equal(a.path, b.path)
    assert a.extras["collision_checks"] < b.extras["collision_checks"] / 2


def test_lazy_samples_refine_only_what_the_search_uses(panda_task, wall):
    """The core takes the sampler's raw rows and refines and checks a row only when it first uses it: the same
    rows as the eager sampler would refine, valid paths, and far fewer Jacobians than refining every row."""
    space, planner = _planner(panda_task, wall, 0)
    sampler = planner.sampler
    _, twin = _planner(panda_task, wall, 0)
    raw = twin.sampler.raw(40)
    refined = space.project(raw, max_iters=twin.sampler.lazy_refine).q
    np.testing.assert_allclose(refined, sampler.candidates(40), atol=1e-12)  # raw rows, then the refinement
    assert len(twin.sampler.raw_many(40)) == 40 and twin.sampler.stats.generated == FIRST_ROWS  # the first batch
    assert twin.sampler.stats.accepted == 0  # raw rows are not samples yet
    sampler.stats = type(sampler.stats)()
    before = space.counts()
    lazy = planner.solve(wall.start, wall.goal, 20.0)
    lazy_jacobians = space.counts()["jacobians"] - before["jacobians"]
    stats = lazy.extras["sampler"]
    assert lazy.solved and 0 < stats["accepted"] <= stats["refined"] < stats["generated"] / 4
    assert stats["checked"] == stats["refined"]  # every row the search made a sample was refined, then checked
    states = densify(lazy.path, space.settings.resolution)[0]
    assert panda_task.constraint.violation(states, space.y).max() <= 1.0
    assert not space.checker.in_collision(states).any() and space.validate_path(lazy.path).valid
    eager_space = twin.space  # refining every row the query drew, as a sampler that checks its rows would
    before = eager_space.counts()
    eager_space.project(twin.sampler.raw(stats["generated"]), max_iters=twin.sampler.lazy_refine)
    assert 2 * lazy_jacobians < eager_space.counts()["jacobians"] - before["jacobians"]


def test_the_core_shortens_its_paths_within_the_query(panda_task, wall):
    """The core's shortcuts (``shortcut`` attempts, native/src/planner.cpp ``Search::shorten``, then its relaxation)
    start from the path its search found (the same search with shortcut=0) and end shorter, with the same ends, valid
    state by state; the relaxation moved waypoints."""
    from manifoldgen.models import pretrained_model_dir
    from manifoldgen.planning import RRTConnect, RRTConnectSettings
    from manifoldgen.specs import make_sampler

    def plan(shortcut):
        space = ConstrainedSpace(panda_task.constraint, wall.condition, wall.checker(panda_task.robot))
        planner = RRTConnect(space, make_sampler(f"cvae:{pretrained_model_dir()}", space, 3), seed=3,
                             settings=RRTConnectSettings(core="native", shortcut=shortcut))
        return space, planner.solve(wall.start, wall.goal, 20.0)

    _, found = plan(0)
    space, short = plan(50)
    assert found.solved and short.solved and short.extras["core"] == "native" and "shortcuts" not in found.extras
    assert short.extras["found_length"] == pytest.approx(found.length, rel=1e-12)
    assert short.extras["shortcuts"] > 0 and short.extras["relaxed"] > 0 and short.length < found.length
    np.testing.assert_array_equal(short.path[[0, -1]], found.path[[0, -1]])
    states = densify(short.path, space.settings.resolution)[0]
    assert panda_task.constraint.violation(states, space.y).max() <= 1.0
    assert panda_task.robot.within_limits(states).all() and not space.checker.in_collision(states).any()


def test_a_path_shortened_in_the_core_times_into_a_valid_trajectory(panda_task, maze, tmp_path):
    """The relaxation keeps the path off the obstacles it pulls it against: a maze path shortened in the core
    (a seed whose taut path grazed a wall between the dense check's states, until the relaxation probed twice as
    far) becomes a time-parameterised trajectory valid at every sample."""
    from manifoldgen.models import pretrained_model_dir
    from manifoldgen.query import run_query, save_path
    from manifoldgen.trajectory import trajectory_of_file

    result, meta = run_query(panda_task, maze[1], f"cvae:{pretrained_model_dir()}", "rrtconnect", seed=14,
                             time_limit=20.0, smooth=True)
    assert result.solved and result.extras["relaxed"] > 0 and result.length < result.extras["found_length"]
    save_path(tmp_path / "p.npz", result, meta)
    check = trajectory_of_file(tmp_path / "p.npz").info["check"]
    assert check["valid"] == check["states"] and check["first_invalid"] is None


def test_reach_bounds_the_stepping_stones_in_both_searches(panda_task, wall):
    """``reach``: a pooled sample is a stepping stone within min(reach, range) of a tree; the core takes the
    setting (another search, its path valid state by state), the Python search's pool gets the same radius,
    and a reach that is not a positive distance is refused in one line."""
    from manifoldgen.models import pretrained_model_dir
    from manifoldgen.planning import RRTConnect, RRTConnectSettings
    from manifoldgen.planning.base import Tree
    from manifoldgen.specs import make_sampler

    def plan(core, reach, seed=2, solve=True):
        space = ConstrainedSpace(panda_task.constraint, wall.condition, wall.checker(panda_task.robot))
        planner = RRTConnect(space, make_sampler(f"cvae:{pretrained_model_dir()}", space, seed), seed=seed,
                             settings=RRTConnectSettings(core=core, reach=reach))
        return space, planner, planner.solve(wall.start, wall.goal, 20.0) if solve else None

    space, short, a = plan("native", 0.3)
    _, full, b = plan("native", 10.0)  # beyond range: range is the radius
    assert short._stone_radius() == 0.3 and full._stone_radius() == full.settings.range == 0.6
    assert a.solved and b.solved and a.extras["core"] == "native"
    assert a.path.shape != b.path.shape or not np.allclose(a.path, b.path)  # the core searched with it
    states = densify(a.path, space.settings.resolution)[0]
    assert panda_task.constraint.violation(states, space.y).max() <= 1.0
    assert panda_task.robot.within_limits(states).all() and not space.checker.in_collision(states).any()
    _, python, _ = plan("python", 0.3, solve=False)
    python._start_pool([Tree(wall.start), Tree(wall.goal)], np.inf)
    assert python.pool.radius == 0.3 and python.pool.free.sum() == python.settings.pool
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ManifoldgenError, match="reach must be a positive distance"):
            RRTConnectSettings(reach=bad).check()


def test_fast_space_projects_and_checks_as_the_python_space_and_never_through_callbacks(panda_task, wall):
    """What collect and the scene targets use: the core's projection and validity where it takes the constraint
    whole (the same iterations, states and verdicts as the numpy reference, its collision checks behind the sphere
    broad phase), the space itself where a part would run through Python callbacks."""
    from manifoldgen.constraints import PlaneConstraint, project
    space, _ = _planner(panda_task, wall, 0)
    fast = native.fast_space(space)
    assert isinstance(fast, native.NativeSpace) and native.fast_space(space) is fast  # built once per space
    assert fast._core.has_spheres
    seeds = panda_task.robot.sample_uniform(64, np.random.default_rng(0))
    ours, theirs = fast.project(seeds.copy()), project(space.constraint, seeds.copy(), space.y)
    np.testing.assert_array_equal(ours.converged, theirs.converged)
    np.testing.assert_array_equal(ours.iterations, theirs.iterations)
    np.testing.assert_allclose(ours.q, theirs.q, rtol=0, atol=1e-8)
    np.testing.assert_array_equal(fast.valid(ours.q), space.valid(ours.q))
    plane = ConstrainedSpace(PlaneConstraint(panda_task.robot, "panda_hand", normals=(0, 0, 1), values=[[0.5]]), [0.5])
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(core_terms, "compiled_part", lambda part, y, robot: "its residual does not trace: a test")
        assert native.fast_space(plane) is plane


def test_a_built_in_term_with_a_bad_type_or_field_is_refused_in_one_line(panda_task, wall):
    """The core builds built-in terms from one table (native/src/builtin_terms.cpp): an unknown type, a missing field,
    a field of the wrong size and an axis out of range are refused naming them, and a good term adds its rows."""
    space, _ = _planner(panda_task, wall, 0)
    core = core_extension.empty_core(space, geometry=False)
    pose = core_terms.constraint_terms(space)[0]
    with pytest.raises(ValueError, match="unknown constraint term type 'plane' .built in: pose, chain"):
        core.add_term("plane", pose)
    with pytest.raises(ValueError, match="constraint term lacks its field 'y'"):
        core.add_term("pose", {key: value for key, value in pose.items() if key != "y"})
    with pytest.raises(ValueError, match="field 'rotation' needs 9 numbers"):
        core.add_term("pose", {**pose, "rotation": [1.0, 0.0, 0.0]})
    with pytest.raises(ValueError, match="pose axes must be 0, 1 or 2"):
        core.add_term("pose", {**pose, "orientation_axes": [3]})
    with pytest.raises(ValueError, match="pose frame id out of range"):
        core.add_term("pose", {**pose, "frame_id": 10**6})
    assert core.m == 0
    core.add_term("pose", pose)
    assert core.m == len(pose["position_axes"]) + len(pose["orientation_axes"])
