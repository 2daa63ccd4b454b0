"""Whole-body balance: the built-in balance tasks (centauro, talos), flat feet, and bad input."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from manifoldgen.constraints import BalanceConstraint, build_constraint, project
from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import save_npz
from manifoldgen.stability import balance_part
from manifoldgen.tasks import BUILTIN_DIR, get_task


@pytest.fixture(scope="module")
def talos():
    return get_task("balance", "talos")


@pytest.fixture(scope="module")
def centauro():
    return get_task("balance", "centauro")


def _arguments(task, **changes):
    return {**balance_part(task.constraint).arguments, "foot_positions": None, "foot_rotations": None, **changes}


def test_balance_tasks_fix_the_feet_where_they_stand(centauro, talos):
    for task, feet, n in ((centauro, 4, 39), (talos, 2, 34)):
        c, home = balance_part(task.constraint), task.home
        assert task.robot.n == n and task.constraint.satisfied(home, task.home_condition)[0]
        stance = np.asarray(c.arguments["stance"])
        for foot, p in zip(c.feet, c.foot_positions):  # fixed where they stand in the reference stance, on z = 0
            np.testing.assert_allclose(task.robot.frame_pose(stance, foot)[0][0], p, atol=1e-9)
        np.testing.assert_allclose(c.contact_points[:, 2], 0.0, atol=c.tolerance[0])
        assert len(c.feet) == feet and c.com_depth(home)[0] >= c.margin
    assert "wheel" not in " ".join(centauro.robot.joints) and "head" not in " ".join(talos.robot.joints)


def test_flat_feet_contract(talos, rng):
    """Talos's soles: Jacobian = finite differences, torch = numpy (differentiable penalty), spec round trip,
    projection lands on configurations whose soles keep their rotation."""
    c, robot, y = talos.constraint, talos.robot, np.array([0.98])
    q = np.clip(talos.home + 0.1 * rng.normal(size=(3, robot.n)), robot.lower, robot.upper)
    F, J = c.jacobian(q, np.broadcast_to(y, (3, 1)))
    for i in range(robot.n):
        dq = np.zeros(robot.n)
        dq[i] = 1e-6
        fd = (c.residual(q + dq, y) - c.residual(q - dq, y)) / 2e-6
        np.testing.assert_allclose(J[:, :, i], fd, atol=1e-5)
    qt = torch.as_tensor(q).requires_grad_(True)
    np.testing.assert_allclose(c.residual(qt, torch.tensor(y)).detach().numpy(), F, atol=1e-9)
    np.testing.assert_allclose(c.inequality(qt, torch.tensor(y)).detach().numpy(), c.inequality(q, y), atol=1e-9)
    far = qt.detach().clone()
    far[:, 0] += 0.5  # base 0.5 m forward: feet off their spots and the CoM past the toes
    far.requires_grad_(True)
    c.penalty(far, torch.tensor(y)).sum().backward()
    assert torch.isfinite(far.grad).all() and far.grad.abs().sum() > 0
    assert (c.inequality(far.detach().numpy(), y) > 0).any()
    rebuilt = build_constraint(robot, c.spec())
    assert rebuilt.spec() == c.spec() and np.array_equal(rebuilt.hull, c.hull)
    res = project(c, q, y)
    ok = res.q[res.converged]
    assert len(ok) and c.violation(ok, y).max() < 1e-3
    for foot, R0 in zip(c.feet, c.foot_rotations):
        np.testing.assert_allclose(robot.frame_pose(ok, foot)[1], np.broadcast_to(R0, (len(ok), 3, 3)), atol=1e-5)


def test_balance_bad_input(centauro, talos):
    robot = centauro.robot
    with pytest.raises(ManifoldgenError, match="'wheel_1' does not touch the ground.*contact"):
        BalanceConstraint(robot, **_arguments(centauro, feet=["wheel_1", "wheel_2", "wheel_3", "wheel_4"]))
    with pytest.raises(ManifoldgenError, match="no support polygon.*contacts"):
        BalanceConstraint(talos.robot, **_arguments(talos, flat=False, contacts=None))
    with pytest.raises(ManifoldgenError, match="no support polygon"):
        BalanceConstraint(robot, **_arguments(centauro, feet=["contact_1", "contact_2"]))
    with pytest.raises(ManifoldgenError, match="only 0.09. m inside .* less than the 0.12 m margin.*not balanced"):
        BalanceConstraint(talos.robot, **_arguments(talos, margin=0.12))
    leaning = np.array(talos.constraint.arguments["stance"])
    leaning[0] += 0.2  # the whole robot 0.2 m forward of its fixed soles: CoM past the toes
    with pytest.raises(ManifoldgenError, match=r"stance's centre of mass \(0\.19.*0\.1.. m outside the support polygon.*not balanced"):
        fixed = {k: v for k, v in talos.constraint.spec().items() if k != "type"}  # soles where they were
        BalanceConstraint(talos.robot, **{**fixed, "stance": leaning.tolist()})
    with pytest.raises(ManifoldgenError, match="needs the feet's 'foot_positions' or a reference 'stance'"):
        BalanceConstraint(robot, **_arguments(centauro, stance=None))
    with pytest.raises(ManifoldgenError, match="stance has 3 values"):
        BalanceConstraint(robot, **_arguments(centauro, stance=[0.0, 0.0, 0.8]))


def _sole_outline(robot, foot: str) -> np.ndarray:
    """(x_lo, x_hi, y_lo, y_hi) in the foot frame of the flat bottom of the foot link's collision mesh: its vertices
    within 2 mm of the lowest (pinocchio's collision model, the reference configuration)."""
    import pinocchio as pin
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    geometry = pin.GeometryData(robot.collision_model)
    pin.updateGeometryPlacements(model, data, robot.collision_model, geometry)
    frame = data.oMf[model.getFrameId(foot)]
    k, obj = next((k, g) for k, g in enumerate(robot.collision_model.geometryObjects)
                  if g.parentJoint == model.frames[model.getFrameId(foot)].parentJoint and hasattr(g.geometry, "vertices"))
    world = np.asarray(obj.geometry.vertices()) @ geometry.oMg[k].rotation.T + geometry.oMg[k].translation
    local = (world - frame.translation) @ frame.rotation
    sole = local[local[:, 2] < local[:, 2].min() + 0.002]
    return np.array([sole[:, 0].min(), sole[:, 0].max(), sole[:, 1].min(), sole[:, 1].max()])


def test_talos_support_polygon_is_the_real_sole(talos):
    """The task's sole corners lie on the ankle mesh's flat bottom, within 1 mm of its outline (they were 3.5 mm
    beyond its toe, and 2 of 10 planned reaches fell in MuJoCo)."""
    c = balance_part(talos.constraint)
    corners = np.asarray(c.arguments["contacts"])[:, :2]
    for foot in c.feet:
        x_lo, x_hi, y_lo, y_hi = _sole_outline(talos.robot, foot)
        assert (corners[:, 0] >= x_lo).all() and (corners[:, 0] <= x_hi).all()
        assert (corners[:, 1] >= y_lo).all() and (corners[:, 1] <= y_hi).all()
        np.testing.assert_allclose([corners[:, 0].min(), corners[:, 0].max(), corners[:, 1].min(), corners[:, 1].max()],
                                   [x_lo, x_hi, y_lo, y_hi], atol=1e-3)


def test_centauro_wheels_stay_upright_over_their_contacts(centauro, rng):
    """Centauro's task holds each wheel's contact point and keeps its contact frame's z axis vertical: projected
    configurations keep every wheel centre over its contact point, where it stood (a wheel cannot swing about its
    ground contact, as it did with the contact points alone: up to 10 cm in MuJoCo)."""
    robot, home, y = centauro.robot, centauro.home, centauro.home_condition
    assert [p.frame for p in centauro.constraint.parts[1:]] == [f"contact_{i}" for i in range(1, 5)]
    q = np.clip(home + 0.15 * rng.normal(size=(8, robot.n)), robot.lower, robot.upper)
    res = project(centauro.constraint, q, y)
    ok = res.q[res.converged]
    assert len(ok) >= 4 and centauro.constraint.satisfied(ok, y).all()
    for i in range(1, 5):
        start = robot.frame_pose(home, f"wheel_{i}")[0][0]
        centres = robot.frame_pose(ok, f"wheel_{i}")[0]
        assert np.abs(centres - start).max() < 0.003  # 0.124 m above the contact, tilt within 0.01 rad: <= 1.3 mm off
        moved = robot.frame_pose(q[res.converged], f"wheel_{i}")[0]
        assert np.abs(moved - start).max() > 0.01  # the seeds had them elsewhere: projection put them back


@pytest.mark.slow
def test_centauro_reach_needs_planning(centauro):
    """The reach scene (the paper's Pholus task): the goal, solved from the left hand's target, is balanced and
    collision-free with the hand on the target, and neither RRT-Connect's direct connection from the stance (projected
    step by step) nor the balance-blind planner's straight one gets there: the post in front of the bottle blocks
    both, so the planner must find a way round it with its sampler's configurations."""
    from manifoldgen.planning import PLANNERS
    from manifoldgen.scene import get_scene
    from manifoldgen.space import ConstrainedSpace
    from manifoldgen.specs import make_sampler
    from manifoldgen.stability import blind_space

    scene = get_scene(centauro, "reach")
    robot, checker = centauro.robot, scene.checker(centauro.robot)
    space = ConstrainedSpace(centauro.constraint, scene.condition, checker)
    assert space.valid(np.stack([scene.start, scene.goal])).all()
    hand = robot.frame_pose(scene.goal, scene.targets["goal"]["frame"])[0][0]
    assert np.abs(hand - scene.targets["goal"]["position"]).max() < 0.01
    for local, sampler, where in (("auto", "project", space), ("direct", "uniform", blind_space(robot, checker))):
        planner = PLANNERS.get("rrtconnect")(where, make_sampler(sampler, where, 0), local=local, seed=0)
        assert planner._direct(scene.start, scene.goal) is None, local
    line = scene.start + np.linspace(0, 1, 21)[:, None] * (scene.goal - scene.start)
    assert any(("post" in pair) for q in line for pair in checker.collisions(q))


def _bad_task(tmp_path, robot, name, *edits):
    """The built-in balance task file of ``robot`` with ``edits`` (old, new) made, written to ``tmp_path / name``."""
    text = (BUILTIN_DIR / f"balance-{robot}.toml").read_text().replace('"scenes/', f'"{BUILTIN_DIR}/scenes/')
    for old, new in edits:
        assert old in text
        text = text.replace(old, new)
    (tmp_path / name).write_text(text)
    return str(tmp_path / name)


def test_balance_bad_input_exits_2_with_one_line(talos, tmp_path):
    """The issue's bad inputs, from the command line: feet off the ground, fewer than 3 contact points (no support
    polygon for the margin), a stance whose CoM is outside, a hand target out of reach while balanced."""
    from typer.testing import CliRunner

    from manifoldgen.cli import app
    soles = ("flat = true", "flat = true\nfoot_positions = [[-0.008847, 0.084817, 0.0], [-0.008847, -0.085183, 0.0]]")
    lean = ("stance = [0.0, 0.0, 1.019272,", "stance = [0.2, 0.0, 1.019272,")  # the robot 0.2 m ahead of its soles
    far = json.loads((BUILTIN_DIR / "scenes" / "talos-reach.json").read_text())
    far["goal"]["position"] = [1.5, 0.3, 0.9]
    (tmp_path / "far.json").write_text(json.dumps(far))
    cases = [
        (["collect", _bad_task(tmp_path, "centauro", "air.toml", ('"contact_3", "contact_4"]', '"wheel_3", "contact_4"]')),
          "--per-condition", "1", "-o", str(tmp_path / "x.npz")], "'wheel_3' does not touch the ground"),
        (["collect", _bad_task(tmp_path, "talos", "points.toml", ("flat = true\ncontacts", "flat = false\n# contacts")),
          "--per-condition", "1", "-o", str(tmp_path / "x.npz")], "no support polygon for the CoM margin"),
        (["collect", _bad_task(tmp_path, "talos", "lean.toml", soles, lean),
          "--per-condition", "1", "-o", str(tmp_path / "x.npz")], "outside the support polygon"),
        (["plan", "balance", "--robot", "talos", "--scene", str(tmp_path / "far.json"), "--sampler", "project",
          "-o", str(tmp_path / "p.npz")], "gripper_left_base_link at the goal target"),
    ]
    for args, needle in cases:
        result = CliRunner().invoke(app, args, terminal_width=400)
        errors = [line for line in result.output.splitlines() if line.startswith("error: ")]
        assert result.exit_code == 2 and len(errors) == 1 and needle in errors[0], result.output
        assert "Traceback" not in result.output and not (tmp_path / "x.npz").exists()


def test_path_stability_counts_states_outside_the_polygon(talos):
    from manifoldgen.stability import blind_space, path_stability
    c, home = talos.constraint, talos.home
    still = path_stability(c, np.stack([home, home]))
    assert still.stable and still.min_depth == pytest.approx(c.com_depth(home)[0]) and still.max_foot_drift < 1e-6
    slid = home.copy()
    slid[0] += 0.15  # the whole robot slides 0.15 m forward: feet leave their spots, CoM passes the toes
    report = path_stability(c, np.stack([home, slid]), resolution=0.005)
    x = np.linspace(0, 0.15, report.states)  # the base's x along the 31 states
    depth = c.com_depth(home[None] + x[:, None] * np.eye(talos.robot.n)[0])
    assert report.states == 31 and report.unstable == int((depth < 0).sum()) > 0
    assert report.unstable_fraction == pytest.approx(np.mean(depth < 0)) and not report.stable
    assert report.max_foot_drift == pytest.approx(0.15, abs=1e-6) and report.min_depth == pytest.approx(depth.min())
    blind = blind_space(talos.robot, None)
    assert blind.valid(slid[None])[0] and blind.problem(slid) is None  # the blind baseline sees no problem
    with pytest.raises(ManifoldgenError, match="no balance constraint"):
        path_stability(get_task("pose", "panda").constraint, np.zeros((1, 7)))


@pytest.fixture(scope="module")
def open_scene(talos, tmp_path_factory):
    """A talos scene without obstacles: the left shoulder swings forward (a query solved in seconds)."""
    goal = talos.home.copy()
    goal[20] -= 0.8
    scene = tmp_path_factory.mktemp("scene") / "open.json"
    scene.write_text(json.dumps({"name": "open", "obstacles": [], "start": talos.home.tolist(), "goal": goal.tolist(),
                                 "condition": talos.home_condition.tolist()}))
    return scene


def test_bench_records_stability_per_run(talos, open_scene):
    """A balance task's bench record carries each solved path's stability, as path_stability finds it."""
    from manifoldgen.bench.planning import Experiment, Method, build, run_once
    from manifoldgen.stability import path_stability
    experiment = Experiment(scene=str(open_scene), task="balance", robot="talos", time_limit=20.0)
    for spec in ("blind=rrtconnect:direct@blind", "rrtconnect:interpolate@project", "rrtconnect@feet-only"):
        record = run_once(experiment, Method.parse(spec), 0)
        assert record["solved"], record.get("why") or record.get("error")
        stability = path_stability(talos.constraint, np.asarray(record["path"]))
        assert record["stability"] == stability.to_dict() and stability.states > 100
    with pytest.raises(ManifoldgenError, match="rrtconnect:direct@blind"):
        build(experiment, Method.parse("rrtconnect@blind"), 0)


def test_outside_checker_rechecks_balance_paths(talos, open_scene, tmp_path):
    """examples/check_path.py (pinocchio + coal only) rechecks feet, the CoM against the support polygon with
    pinocchio's centerOfMass, limits and collisions from the path file alone; a path that slides the robot off
    its feet is refused with its unstable states counted."""
    from manifoldgen.query import run_query
    from manifoldgen.scene import get_scene
    from manifoldgen.stability import path_stability
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
    from check_path import outside_check
    from recheck import EXIT_INVALID, EXIT_VALID

    result, meta = run_query(talos, get_scene(talos, str(open_scene)), "project", "rrtconnect", seed=0, time_limit=20.0)
    assert result.solved
    ours = path_stability(talos.constraint, result.path, meta["validation"]["resolution"])
    middle = result.path[:2].mean(axis=0)
    middle[0] += 0.15  # a detour with the whole robot 0.15 m forward: feet dragged, CoM past the toes
    for name, path in (("ok", result.path), ("slid", np.insert(result.path, 1, middle, axis=0))):
        save_npz(tmp_path / f"{name}.npz", meta, path=path)
    report = outside_check(tmp_path / "ok.npz")
    assert report["status"] == EXIT_VALID and report["stability"]["unstable"] == 0
    assert report["stability"]["states"] == ours.states
    assert report["stability"]["min_depth"] == pytest.approx(ours.min_depth, abs=1e-6)  # pinocchio's CoM = ours
    bad = outside_check(tmp_path / "slid.npz")
    assert bad["status"] == EXIT_INVALID and "left_sole_link position x" in bad["reason"]
    assert bad["stability"]["unstable"] > 0 and bad["stability"]["max_foot_drift"] == pytest.approx(0.15, abs=0.01)


def test_balance_snapshots_draw_the_support_polygon_and_the_com(talos, tmp_path):
    """Paper Fig. 6: the strip shows the support polygon (green) and the CoM projection (green inside)."""
    import matplotlib.image

    from manifoldgen.demos import DEMOS
    from manifoldgen.scene import Scene
    from manifoldgen.viz.snapshots import draw_snapshots
    goal = talos.home.copy()
    goal[20] -= 0.8
    scene = Scene("open", [], None, talos.home, goal, talos.home_condition)
    out = draw_snapshots(np.stack([talos.home, goal]), talos, scene, tmp_path / "strip.png", count=2)
    pixels = matplotlib.image.imread(out)[..., :3]
    green = np.all(np.abs(pixels - np.array([0.0, 128 / 255, 0.0])) < 0.02, axis=2)
    assert green.sum() > 50  # matplotlib's "green": the polygon and the CoM's ground projection
    assert DEMOS["balance"] == "manifoldgen.demos.balance"


def test_unreachable_hand_target_and_bad_base_bounds(talos):
    """A reach target no balanced configuration attains is refused with the fix; so are malformed base bounds."""
    from manifoldgen.robot import Robot
    from manifoldgen.targets import solve_target
    with pytest.raises(ManifoldgenError, match="no collision-free configuration on the task's manifold .* gripper_left_"
                                               "base_link at the goal target .* move the target within reach"):
        solve_target(talos.constraint, talos.home_condition, {"position": [1.5, 0.3, 0.9],
                                                             "frame": "gripper_left_base_link"}, None, "goal")
    with pytest.raises(ManifoldgenError, match=r"base_bounds must be \[\[low\], \[high\]\] of x, y, z"):
        Robot.load("talos", ["torso_1_joint"], floating_base=True, base_bounds=[[0, 0], [1, 1]])
    angled = Robot.load("talos", ["torso_1_joint"], floating_base=True,
                        base_bounds=[[-1, -1, 0, -0.5, -0.2, -9], [1, 1, 2, 0.5, 0.2, 9]])
    np.testing.assert_allclose(angled.lower[:6], [-1, -1, 0, -0.5, -0.2, -np.pi])
    np.testing.assert_allclose(angled.upper[:6], [1, 1, 2, 0.5, 0.2, np.pi])
