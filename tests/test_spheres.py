"""Sphere models: every point of each mesh (surface and solid) inside some sphere; the sphere check never
calls free a state coal finds in collision; cache; exact fallbacks for what has no spheres."""

import shutil
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest

from manifoldgen import spheres
from manifoldgen.collision import CollisionChecker, cache_dir
from manifoldgen.io import load_npz
from manifoldgen.shapes import Obstacle, Pose, held_checker
from manifoldgen.tasks import get_task


@pytest.fixture(scope="module")
def panda_model(panda_task):
    return spheres.sphere_model(panda_task.robot)


@pytest.fixture(scope="module")
def pr2():
    return get_task("dualarm", "pr2")


PR2_LINKS = ("l_upper_arm_link_0", "l_forearm_link_0", "l_gripper_palm_link_0", "r_elbow_flex_link_0",
             "r_gripper_l_finger_link_0", "torso_lift_link_0", "base_link_0")


def _surface_points(tris: np.ndarray, rng, per: int = 8) -> np.ndarray:
    """(T * per + 3 T, 3) points on the triangles: their vertices and random points."""
    w = rng.dirichlet(np.ones(3), size=(len(tris), per))
    return np.concatenate([np.einsum("tpk,tkj->tpj", w, tris).reshape(-1, 3), tris.reshape(-1, 3)])


def _winding(points: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(P,) winding numbers of a closed surface around points (solid angles, Van Oosterom-Strackee)."""
    a, b, c = (tris[None, :, k] - points[:, None] for k in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
    num = np.einsum("ptj,ptj->pt", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("ptj,ptj->pt", a, b) * lc + np.einsum("ptj,ptj->pt", b, c) * la \
        + np.einsum("ptj,ptj->pt", c, a) * lb
    return np.abs(2 * np.arctan2(num, den).sum(1) / (4 * np.pi))


def _solid_points(tris: np.ndarray, rng, count: int = 400) -> np.ndarray:
    """Random points inside a closed surface (rejection from its box by winding number)."""
    lo, hi = tris.reshape(-1, 3).min(0), tris.reshape(-1, 3).max(0)
    candidates = rng.uniform(lo, hi, size=(count, 3))
    return candidates[_winding(candidates, tris) > 0.5]


def _uncovered(points: np.ndarray, centers: np.ndarray, radii: np.ndarray) -> int:
    """How many points lie outside every sphere."""
    gap = np.linalg.norm(points[:, None] - centers[None], axis=2) - radii
    return int(np.sum(gap.min(1) > 0))


def _check_covered(geom: pin.GeometryModel, model: spheres.SphereModel, i: int, rng) -> int:
    """Surface (and, for closed meshes, solid) points of geometry ``i`` outside its spheres; returns how
    many solid points were tested."""
    g = geom.geometryObjects[i]
    tris = spheres.triangles_of(g.geometry)
    mine = model.geometry == i
    assert mine.any(), f"{g.name} has no spheres"
    assert np.all(model.joint[mine] == g.parentJoint)
    M = g.placement.homogeneous
    inside = _solid_points(tris, rng) if spheres.solid_volume(tris) == abs(np.einsum(
        "ti,ti->", tris[:, 0], np.cross(tris[:, 1], tris[:, 2]))) / 6 else np.zeros((0, 3))
    for points in (_surface_points(tris, rng), inside):
        in_joint = points @ M[:3, :3].T + M[:3, 3]
        assert _uncovered(in_joint, model.center[mine], model.radius[mine]) == 0, g.name
    return len(inside)


def test_panda_spheres_cover_every_mesh_and_box(panda_task, panda_model, rng):
    geom = panda_task.robot.collision_model
    assert panda_model.unfitted == ()
    assert set(panda_model.geometry.tolist()) == set(range(len(geom.geometryObjects)))
    counts = panda_model.counts()
    assert counts.max() <= 24 and len(panda_model) <= 160  # tens per link
    solid = sum(_check_covered(geom, panda_model, i, rng) for i in range(len(geom.geometryObjects)))
    assert solid > 1000  # the solids were sampled, not only the surfaces
    assert np.all(panda_model.union_volume >= panda_model.solid_volume * 0.9)


@pytest.mark.slow
def test_pr2_arm_and_base_spheres_cover_their_meshes(pr2, rng):
    geom = pr2.robot.collision_model
    ids = [i for i, g in enumerate(geom.geometryObjects) if g.name in PR2_LINKS]
    model = spheres.fit_model(geom, ids)
    assert sorted(set(model.geometry.tolist())) == ids
    for i in ids:
        _check_covered(geom, model, i, rng)


@pytest.mark.parametrize("shape", [coal.Box(0.3, 0.1, 0.05), coal.Cylinder(0.04, 0.3), coal.Sphere(0.07)])
def test_primitives_are_covered_solid(shape, rng):
    centers, radii, solid, union = spheres.fit_geometry(shape)
    points = rng.uniform(-0.2, 0.2, size=(20000, 3))
    if isinstance(shape, coal.Box):
        points = points[np.all(np.abs(points) <= np.asarray(shape.halfSide), axis=1)]
    elif isinstance(shape, coal.Cylinder):
        points = points[(np.linalg.norm(points[:, :2], axis=1) <= shape.radius)
                        & (np.abs(points[:, 2]) <= shape.halfLength)]
    else:
        points = points[np.linalg.norm(points, axis=1) <= shape.radius]
    assert len(points) > 100 and _uncovered(points, centers, radii) == 0
    assert union >= solid


def _random_scene(rng, count: int = 9) -> list[Obstacle]:
    """Boxes, spheres and cylinders around a panda's reach."""
    out = []
    for k in range(count):
        kind = ("box", "sphere", "cylinder")[k % 3]
        q = rng.normal(size=4)
        pose = Pose(rng.uniform([-0.7, -0.7, 0.0], [0.7, 0.7, 1.0]), q / np.linalg.norm(q))
        out.append(Obstacle(f"o{k}", kind, pose, size=rng.uniform(0.03, 0.25, 3), radius=float(rng.uniform(0.03, 0.12)),
                            length=float(rng.uniform(0.05, 0.4))))
    return out


def test_panda_sphere_check_is_conservative_against_coal(panda_task, panda_model, rng):
    robot = panda_task.robot
    checker = CollisionChecker(robot, obstacles=[o.geometry_object() for o in _random_scene(rng)])
    fast = spheres.SphereChecker(checker, panda_model)
    assert fast.pairs["exact"] == 0 and fast.pairs["obstacle"] > 0 and fast.pairs["self"] > 0
    q = robot.sample_uniform(600, rng)
    exact, sphere = checker.in_collision(q), fast.in_collision(q)
    assert 50 < exact.sum() < 550  # both outcomes are exercised
    assert not np.any(exact & ~sphere)  # never free where coal collides
    false_positive = np.mean(sphere[~exact])
    print(f"panda random scene: false positives {false_positive:.1%} of {np.sum(~exact)} free states")
    assert false_positive < 0.35
    # batching does not change results
    assert np.array_equal(fast.in_collision(q[:7]), sphere[:7])


@pytest.mark.slow
def test_pr2_held_tray_and_self_pairs_are_conservative_with_exact_fallback(pr2, rng):
    """Arm and torso links have spheres; the others (head, base, grippers ...) fall back to coal, said once."""
    robot = pr2.robot
    geom = robot.collision_model
    ids = [i for i, g in enumerate(geom.geometryObjects) if g.name in PR2_LINKS]
    model = spheres.fit_model(geom, ids)
    from manifoldgen.shapes import Attached
    checker = held_checker(robot, Attached.from_dict(pr2.attached),
                           [o.geometry_object() for o in _random_scene(rng, 6)])
    with pytest.warns(UserWarning, match="use coal's exact check"):
        fast = spheres.SphereChecker(checker, model)
    assert fast.pairs["exact"] > 0 and fast.pairs["self"] > 0
    assert np.isin(checker.attached_ids, fast.geometry).all()  # the tray got spheres
    q = robot.sample_uniform(250, rng)
    exact, sphere = checker.in_collision(q), fast.in_collision(q)
    assert exact.sum() > 20 and not np.any(exact & ~sphere)


def test_mesh_obstacle_uses_coal_and_says_so(panda_task, panda_model, rng, tmp_path):
    robot = panda_task.robot
    mesh = next(g.meshPath for g in robot.collision_model.geometryObjects if g.meshPath.endswith(".stl"))
    obstacle = Obstacle("part", "mesh", Pose([0.4, 0.0, 0.4]), mesh=mesh)
    checker = CollisionChecker(robot, obstacles=[obstacle.geometry_object()])
    with pytest.warns(UserWarning, match="part \\(a mesh obstacle\\)"):
        fast = spheres.SphereChecker(checker, panda_model)
    q = robot.sample_uniform(200, rng)
    exact = checker.in_collision(q)
    assert not np.any(exact & ~fast.in_collision(q))


def test_a_refit_gives_the_cached_spheres(panda_task, panda_model):
    """Fitting is deterministic, and a faster fit must not move a sphere: a refit of panda's hand and last link gives
    the spheres the cache (or the package) holds for them, to rounding (the shipped ones were fitted on another
    machine, whose numpy kernels may round the last bit otherwise: 6e-17 m seen)."""
    geom = panda_task.robot.collision_model
    ids = [i for i, g in enumerate(geom.geometryObjects) if g.name.startswith(("panda_hand", "panda_link7"))]
    refit, kept = spheres.fit_model(geom, ids), np.isin(panda_model.geometry, ids)
    assert len(ids) == 2 and len(refit) == kept.sum() > 0
    np.testing.assert_allclose(refit.center, panda_model.center[kept], rtol=0, atol=1e-12)
    np.testing.assert_allclose(refit.radius, panda_model.radius[kept], rtol=0, atol=1e-12)
    assert np.array_equal(refit.center, spheres.fit_model(geom, ids).center)  # the same machine: the same bits


def test_a_mesh_in_two_parts_is_fitted_across_the_gap(rng):
    """Two tetrahedra 1 m apart: the slabs between them hold no triangle, and every vertex and random point of the
    two solids still lies in a sphere."""
    corners = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]])
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    mesh = coal.BVHModelOBBRSS()
    mesh.beginModel(8, 8)
    for shift in (0.0, 1.0):
        for face in faces:
            mesh.addTriangle(*(corners[k] + [shift, 0, 0] for k in face))
    mesh.endModel()
    fit, why = spheres.fit_or_reason(mesh)
    assert why is None, why
    centers, radii = fit[:2]
    weights = rng.dirichlet(np.ones(4), size=500)
    points = np.concatenate([corners, corners + [1.0, 0, 0], weights @ corners, weights @ corners + [1.0, 0, 0]])
    gaps = np.linalg.norm(points[:, None] - centers[None], axis=2) - radii[None]
    assert np.all(gaps.min(axis=1) <= 0)


def test_unsupported_geometry_gets_no_spheres(panda_task):
    geom = panda_task.robot.collision_model.copy()
    geom.addGeometryObject(pin.GeometryObject("capsule", 7, pin.SE3.Identity(), coal.Capsule(0.02, 0.1)))
    steps = []  # a progress bar's steps: one per object, fitted or not
    model = spheres.fit_model(geom, [len(geom.geometryObjects) - 1], fitted=lambda: steps.append(1))
    assert model.unfitted == (len(geom.geometryObjects) - 1,) and len(model) == 0 and len(steps) == 1


def _model_file(robot) -> Path:
    """The file the robot's model was read from or written to: the user's cache, else the package's."""
    path = spheres.cache_path(robot, spheres.cache_stamp(robot))
    return path if path.exists() else spheres.cache.SHIPPED / path.name


def test_model_is_cached_and_a_damaged_cache_is_refused(panda_task, panda_model, monkeypatch, tmp_path):
    stamp = spheres.cache_stamp(panda_task.robot)
    shared = _model_file(panda_task.robot)  # read or written by the panda_model fixture
    monkeypatch.setenv("MANIFOLDGEN_CACHE", str(tmp_path))  # a copy of it in this test's own cache, to damage
    (tmp_path / "spheres").mkdir()
    shutil.copy(shared, spheres.cache_path(panda_task.robot, stamp))
    files = list((cache_dir() / "spheres").glob("panda-*.npz"))
    assert len(files) == 1
    monkeypatch.setattr(spheres.cache, "fit_model", lambda *a, **k: pytest.fail("refitted despite a valid cache"))
    again = spheres.sphere_model(panda_task.robot)
    assert np.array_equal(again.center, panda_model.center) and again.unfitted == panda_model.unfitted
    data = dict(np.load(files[0]))
    data["radius"] = data["radius"] * 0.5  # shrunk spheres would no longer cover
    np.savez(files[0], **data)
    with pytest.warns(UserWarning, match="do not match their checksum\\); recomputing"):
        stamp = spheres.cache_stamp(panda_task.robot)
        assert spheres.read_cache(files[0], stamp, len(panda_model.solid_volume)) is None


def test_a_shipped_model_is_read_where_the_cache_has_none(panda_task, panda_model, private_cache, monkeypatch,
                                                          tmp_path):
    """The package's models (spheres.cache.SHIPPED) serve a robot whose files they were made for: an empty cache
    reads them and fits nothing. Every file the package ships passes the cache's own checks."""
    stamp = spheres.cache_stamp(panda_task.robot)
    shipped = tmp_path / "shipped"
    shipped.mkdir()
    shutil.copy(_model_file(panda_task.robot), shipped / spheres.cache_path(panda_task.robot, stamp).name)
    with monkeypatch.context() as patch:
        patch.setattr(spheres.cache, "SHIPPED", shipped)
        patch.setattr(spheres.cache, "fit_model", lambda *a, **k: pytest.fail("fitted despite a shipped model"))
        model = spheres.sphere_model(panda_task.robot)
    assert np.array_equal(model.radius, panda_model.radius) and not any(private_cache.rglob("*.npz"))
    files = sorted(spheres.cache.SHIPPED.glob("*.npz"))
    assert {f.name.rsplit("-", 1)[0] for f in files} >= {"panda", "pr2", "talos", "centauro", "baxter", "point"}
    for file in files:
        meta, arrays = load_npz(file, ())
        assert spheres.read_cache(file, {key: meta[key] for key in stamp}, len(arrays["solid_volume"])) is not None, \
            file.name


def test_tight_pairs_go_to_coal_and_stay_conservative(panda_task, panda_model, rng, monkeypatch):
    robot = panda_task.robot
    checker = CollisionChecker(robot)
    q = robot.sample_uniform(400, rng)
    exact = checker.in_collision(q)
    default = spheres.SphereChecker(checker, panda_model)
    monkeypatch.setattr(spheres.checker, "TIGHT_RATE", 0.01)  # nearly every self pair whose spheres touch goes to coal
    strict = spheres.SphereChecker(checker, panda_model, typical=q[200:])
    assert strict.pairs["tight"] > default.pairs["tight"] and strict.pairs["exact"] == strict.pairs["tight"]
    assert len(strict.exact_pairs) == strict.pairs["exact"]
    loose, tight = default.in_collision(q), strict.in_collision(q)
    assert not np.any(exact & ~loose) and not np.any(exact & ~tight)
    assert np.sum(tight & ~exact) < np.sum(loose & ~exact)


TALOS_PARTS = ("leg_left_3", "leg_right_3", "leg_left_4", "leg_right_4", "torso_2", "arm_left_2", "arm_right_2",
               "base_link")


@pytest.mark.slow
def test_the_cores_per_pair_broad_phase_keeps_every_verdict_on_talos():
    """Spheres per pair, then convex hulls, then coal: every verdict is coal's alone, on talos's close links (thighs,
    shins, torso beside the shoulders) in uniform states and states near its stance, visited in order as a path
    check does (the hulls' GJK is warm-started from the previous state)."""
    pytest.importorskip("manifoldgen_core")
    from manifoldgen import native
    from manifoldgen.space import ConstrainedSpace

    task = get_task("balance", "talos")
    robot = task.robot
    space = ConstrainedSpace(task.constraint, task.home_condition, held_checker(robot, None, []))
    core = native.core_space(space)
    geom = robot.collision_model
    parts = [i for i, g in enumerate(geom.geometryObjects) if g.name.startswith(TALOS_PARTS)]
    model = spheres.fit_model(geom, parts)  # the other geometries stay exact: a partial model is allowed
    rng = np.random.default_rng(2)
    near = np.clip(task.home + rng.normal(0, 0.2, (150, robot.n)), robot.lower, robot.upper)
    walk = task.home + np.linspace(0, 1, 150)[:, None] * (near[0] - task.home)  # consecutive close states
    q = np.concatenate([robot.sample_uniform(150, rng), near, walk])
    limit = np.full(len(q), np.inf)  # collision alone decides
    exact = core.codes(q, limit, True, True)
    native.set_spheres(core, {"joint": model.joint, "center": model.center, "radius": model.radius,
                              "geometry": model.geometry, "exact": [(parts[0], parts[1])]})
    flagged = core.codes(q, limit, True, False)
    before = core.counts()
    np.testing.assert_array_equal(core.codes(q, limit, True, True), exact)
    after = core.counts()
    collide = exact == 4
    assert collide.sum() >= 10 and not collide.all() and not np.any(collide & ~(flagged == 4))
    # every state that reached the collision test (limits and the CoM margin come first) had the sphere test;
    # those the spheres flagged went on to coal, the others did not
    assert after["sphere_checks"] - before["sphere_checks"] == np.sum((exact == 0) | collide) > 100
    assert after["collision_checks"] - before["collision_checks"] == np.sum(flagged == 4)


@pytest.mark.slow
def test_a_mesh_coal_cannot_hull_goes_to_coal_on_centauro():
    """coal refuses the convex hull of centauro's pelvis mesh ("Too many neighbors"): the core's sphere model still
    loads, the pelvis's pairs go from the spheres to coal, and every verdict is coal's (drinkcan's robot)."""
    pytest.importorskip("manifoldgen_core")
    from manifoldgen import native
    from manifoldgen.scene import get_scene
    from manifoldgen.space import ConstrainedSpace

    task = get_task("drinkcan")
    robot = task.robot
    space = ConstrainedSpace(task.constraint, task.home_condition, get_scene(task, "drinkcan").checker(robot))
    core = native.core_space(space)
    geom = robot.collision_model
    parts = [i for i, g in enumerate(geom.geometryObjects) if g.name.startswith(("pelvis", "torso", "arm1_"))]
    model = spheres.fit_model(geom, parts)  # the other geometries stay exact: a partial model is allowed
    rng = np.random.default_rng(5)
    q = np.concatenate([robot.sample_uniform(100, rng),
                        np.clip(task.home + rng.normal(0, 0.3, (100, robot.n)), robot.lower, robot.upper)])
    limit = np.full(len(q), np.inf)  # collision alone decides
    exact = core.codes(q, limit, True, True)
    native.set_spheres(core, {"joint": model.joint, "center": model.center, "radius": model.radius,
                              "geometry": model.geometry, "exact": []})
    np.testing.assert_array_equal(core.codes(q, limit, True, True), exact)
    assert 10 <= np.sum(exact == 4) < len(q)
