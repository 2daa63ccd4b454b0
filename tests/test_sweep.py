"""Certified sweeps in the core's dense path check (sweeps.cpp, "Certified sweeps"): the motion bound holds on
random spans, a certified span never holds a colliding state, and validate_path with sweeps gives the same
report as state by state (panda maze and wall, talos reach), with fewer collision queries."""

import numpy as np
import pinocchio as pin
import pytest

from manifoldgen import native, spheres
from manifoldgen.scene import get_scene
from manifoldgen.space import ConstrainedSpace, densify
from manifoldgen.tasks import get_task

from certified_paths import compare_certified, manifold_polylines

pytestmark = pytest.mark.slow  # the quick loop (pytest -m "not slow") leaves this module out

pytest.importorskip("manifoldgen_core", reason="the compiled core is not built (scripts/setup.sh builds it)")

# talos's links near each other and the scene (a partial model keeps the fit short; every other geometry's pairs
# are exact pairs, which the sweep tests on convex hulls)
TALOS_PARTS = ("leg_left_3", "leg_right_3", "leg_left_4", "leg_right_4", "torso_2", "arm_left_2", "arm_right_2",
               "arm_left_7", "arm_right_7", "gripper_left", "gripper_right", "base_link")


def _problem(kind: str):
    """(robot, space, core with sphere models set, reference state, spread of random states, sphere joints (S,))
    of a scene."""
    if kind == "talos":
        task = get_task("balance", "talos")
        scene = get_scene(task, "reach")
        geom = task.robot.collision_model
        parts = [i for i, g in enumerate(geom.geometryObjects) if g.name.startswith(TALOS_PARTS)]
        model = spheres.fit_model(geom, parts)
        checker = scene.checker(task.robot)  # the pairs among these parts and with the scene only
        keep = set(parts) | set(checker.obstacle_ids)
        pairs = [(p.first, p.second) for p in checker.geom.collisionPairs if {p.first, p.second} <= keep]
        checker.geom.removeAllCollisionPairs()
        for a, b in pairs:
            checker.geom.addCollisionPair(pin.CollisionPair(a, b))
        checker.geom_data = pin.GeometryData(checker.geom)
        checker._broad = pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(task.robot.model, checker.geom,
                                                                                 checker.geom_data)
        space = ConstrainedSpace(task.constraint, scene.condition, checker)
        core = native.core_space(space)
        native.set_spheres(core, {"joint": model.joint, "center": model.center, "radius": model.radius,
                                  "geometry": model.geometry, "exact": [(parts[0], parts[1])]})
        return task.robot, space, core, task.home, 0.06, np.asarray(model.joint)
    task = get_task("pose", "panda")
    scene = get_scene(task, kind)
    space = ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))
    core = native.core_space(space)
    models = native.space_spheres(space)
    native.set_spheres(core, models)
    return task.robot, space, core, scene.start, 0.8, np.asarray(models["joint"])


@pytest.fixture(scope="module", params=["maze", "wall", "talos"])
def problem(request):
    return _problem(request.param)


def _polylines(robot, reference, spread, count, rng, waypoints=4):
    """``count`` random polylines (waypoints, n) around ``reference``, inside the joint limits."""
    return [np.clip(reference + rng.normal(0, spread, (waypoints, robot.n)), robot.lower, robot.upper)
            for _ in range(count)]


def test_the_motion_bound_holds_on_random_spans(problem):
    """No sphere centre moves farther from its place at a span's middle state than its bound, at the dense states
    and between them (the bound covers the polyline through the states, waypoints included)."""
    robot, _, core, reference, spread, _ = problem
    rng = np.random.default_rng(0)
    assert core.sweeps, core.sweep_report()
    worst = 0.0
    for path in _polylines(robot, reference, spread, 6, rng, waypoints=3):
        states = densify(path, 0.005)[0]
        for k in (2, 7, 16, 40):
            start = int(rng.integers(0, len(states) - k))
            span = np.ascontiguousarray(states[start:start + k])
            bound = core.sweep_bounds(span)
            middle = core.sphere_centers(span[k // 2])
            fine = densify(span, 0.001)[0]  # the polyline between the states too
            for q in fine[:: max(1, len(fine) // 25)]:
                moved = np.linalg.norm(core.sphere_centers(q) - middle, axis=1)
                assert np.all(moved <= bound + 1e-12)
                worst = max(worst, float(np.max(moved[bound > 0] / bound[bound > 0])))
    assert worst > 0.3  # a bound, not a blanket: some sphere moves a good part of it


def test_the_motion_bounds_hold_relative_to_every_support(problem):
    """A pair's spheres are grown by their motion below the pair's deepest common joint: no sphere centre moves
    farther, in the frame of any joint supporting it, than its bound at that joint's depth; and the rate bound the
    sphere tests try first covers the motion in the world (brute force at and between the states of random spans)."""
    robot, _, core, reference, spread, joints = problem
    rng = np.random.default_rng(3)
    supports = [list(robot.model.supports[j]) for j in range(robot.model.njoints)]
    depth = max(len(supports[j]) for j in joints)
    tested, worst = 0, 0.0
    for path in _polylines(robot, reference, spread, 3, rng, waypoints=3):
        states = densify(path, 0.005)[0]
        for k in (3, 16):
            start = int(rng.integers(0, len(states) - k))
            span = np.ascontiguousarray(states[start:start + k])
            fine = densify(span, 0.001)[0]
            fine = np.vstack([span[k // 2], fine[:: max(1, len(fine) // 12)]])
            centers = np.stack([core.sphere_centers(q) for q in fine])  # (Q, S, 3)
            poses = robot.joint_poses(fine, sorted(set(joints.tolist())))
            moved = np.linalg.norm(centers - centers[0], axis=2)
            assert np.all(moved <= core.sweep_bounds(span, rates=True) + 1e-12)
            for common in range(depth):
                bound = core.sweep_bounds(span, common)
                for s in np.flatnonzero(np.isfinite(bound)):
                    frame = poses[supports[joints[s]][common]]  # (Q, 4, 4)
                    local = np.einsum("qji,qj->qi", frame[:, :3, :3], centers[:, s] - frame[:, :3, 3])
                    shift = np.linalg.norm(local - local[0], axis=1).max()
                    assert shift <= bound[s] + 1e-12
                    tested += 1
                    worst = max(worst, shift / bound[s] if bound[s] > 0 else 0.0)
    assert tested > 100 and worst > 0.3  # bounds, not blankets


def test_a_certified_span_never_holds_a_colliding_state(problem):
    """Brute force on short spans: every span the sweep certifies is collision-free state by state for coal, and
    between states; spans that collide exist and are refused."""
    robot, space, core, reference, spread, _ = problem
    rng = np.random.default_rng(1)
    certified = refused_colliding = 0
    for path in _polylines(robot, reference, spread, 10, rng, waypoints=3):
        states = densify(path, 0.005)[0]
        for k in (2, 3, 5, 9):
            for start in rng.integers(0, len(states) - k, 3):
                span = np.ascontiguousarray(states[start:start + k])
                collides = space.checker.in_collision(densify(span, 0.0025)[0]).any()
                if core.sweep_free(span):
                    assert not collides
                    certified += 1
                else:
                    refused_colliding += int(collides)
    assert certified >= 10 and refused_colliding >= 5


def test_sweeps_give_the_state_by_state_report(problem):
    """Random paths, valid and invalid (limits, collisions; with the real tolerance also the constraint): every
    field of validate_path's report equals the state-by-state one, for fewer per-state checks."""
    robot, space, core, reference, spread, _ = problem
    rng = np.random.default_rng(2)
    tolerance = np.asarray(space.constraint.tolerance, float)
    paths = [p for scale in (40, 4, 1) for p in _polylines(robot, reference, spread / scale, 8, rng)]
    reasons, lengths = set(), []
    counts = {True: 0, False: 0}
    try:
        for loose in (True, False):
            core.set_tolerance(tolerance * (1e6 if loose else 1.0))  # loose: collisions decide
            for path in paths:
                report = {}
                for sweeps in (False, True):
                    core.set_sweeps(sweeps)
                    before = core.counts()
                    report[sweeps] = core.validate_path(np.ascontiguousarray(path))
                    after = core.counts()
                    counts[sweeps] += after["sphere_checks"] - before["sphere_checks"]
                assert report[True] == report[False]
                valid, _, first, reason, _, states = report[True]
                reasons.add(reason)
                lengths.append(states)
    finally:
        core.set_tolerance(tolerance)
        core.set_sweeps(True)
    assert {0, 2, 4} <= reasons  # valid paths, constraint and collision failures
    assert max(lengths) > 100
    assert counts[True] < counts[False] / 2



def test_certified_constraints_give_the_exact_report(problem):
    """With sphere models (certified sweeps), validate_path(certify=True) gives the state-by-state report (see
    certified_paths) for fewer evaluations (on talos's reach about half: its 1 cm tolerance leaves room; the panda's
    levers use up its slack in a state or two)."""
    robot, space, core, reference, spread, _ = problem
    reasons, evaluations = compare_certified(core, manifold_polylines(space, core, reference, spread, 5))
    assert {0, 2} <= reasons  # valid paths and constraint failures between the waypoints
    assert evaluations[True] < evaluations[False]


def test_an_unbounded_robot_geometry_turns_sweeps_off_and_keeps_the_report():
    """A link geometry with no bound (a half-space on the panda's hand, in no collision pair) has no motion bound:
    the core says why it sweeps no span, still says so after building the constraint's rates (certify=True), and
    checks paths state by state with the reports of the same robot without it."""
    import coal

    task = get_task("pose", "panda")
    scene = get_scene(task, "wall")
    cores = []
    for unbounded in (False, True):
        checker = scene.checker(task.robot)
        if unbounded:
            hand = task.robot.model.njoints - 1
            plate = coal.Halfspace(np.array([0.0, 0.0, 1.0]), -5.0)
            checker.geom.addGeometryObject(pin.GeometryObject("unbounded_plate", hand, pin.SE3.Identity(), plate))
            checker.geom_data = pin.GeometryData(checker.geom)
        space = ConstrainedSpace(task.constraint, scene.condition, checker)
        core = native.core_space(space)
        native.set_spheres(core, native.space_spheres(space))
        cores.append(core)
    bounded, unbounded = cores
    assert bounded.sweeps and bounded.sweep_report() == ""
    assert not unbounded.sweeps and unbounded.sweep_report() == "geometry unbounded_plate is unbounded"
    paths = manifold_polylines(space, unbounded, scene.start, 0.8, seed=4, count=3)
    reasons = set()
    for path in paths:
        for certify in (False, True):
            before = unbounded.counts()["sweep_checks"]
            report = unbounded.validate_path(np.ascontiguousarray(path), certify=certify)
            assert unbounded.counts()["sweep_checks"] == before
            expected = bounded.validate_path(np.ascontiguousarray(path), certify=certify)
            assert report[0] == expected[0] and report[2:] == expected[2:]
            np.testing.assert_allclose(report[1], expected[1], rtol=1e-12)
            reasons.add(report[3])
    assert unbounded.sweep_report() == "geometry unbounded_plate is unbounded" and not unbounded.sweeps
    assert {0, 4} <= reasons  # valid paths and collisions among them
