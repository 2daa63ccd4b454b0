"""Bad input refused alike: every case runs through the Python space / search and through the compiled
core (:class:`~manifoldgen.native.NativeSpace`, ``core="native"``), once with a built-in constraint (all
C++) and once with a Python one (compiled into C++, and through callbacks); both must raise the same
ManifoldgenError message, or give the same verdict where the Python rule answers instead of raising (NaN states
are invalid)."""

import numpy as np
import pytest

from manifoldgen import native
from manifoldgen.constraints import Condition, Constraint, PlaneConstraint, PoseConstraint
from manifoldgen.errors import ManifoldgenError
from manifoldgen.space import ConstrainedSpace

pytest.importorskip("manifoldgen_core", reason="the compiled core is not built (scripts/setup.sh builds it)")

DOWN = np.diag([1.0, -1.0, -1.0])


def _constraint(robot, kind: str, **options) -> Constraint:
    """The wall task's manifold as a built-in pose (C++ terms) or a Python plane (compiled or callbacks)."""
    if kind == "pose":
        return PoseConstraint(robot, options.pop("frame", "panda_hand_tcp"), DOWN, [[0.3], [0.6]], **options)
    return PlaneConstraint(robot, options.pop("frame", "panda_hand_tcp"), [[0, 0, 1]], [[0.3], [0.6]], **options)


@pytest.fixture(scope="module", params=["pose", "plane", "plane-callbacks"])
def problem(request, panda_task):
    from manifoldgen.scene import get_scene
    scene = get_scene(panda_task, "wall")
    kind = request.param.split("-")[0]
    space = ConstrainedSpace(_constraint(panda_task.robot, kind), scene.condition, scene.checker(panda_task.robot))
    core = native.core_space(space, compile=request.param != "plane-callbacks")
    return panda_task, scene, space, native.NativeSpace(space, core), kind


def _outcome(call):
    """('error', message) or ('ok', the value as a comparable tuple)."""
    try:
        value = call()
    except ManifoldgenError as exc:
        return "error", str(exc)
    if hasattr(value, "to_dict"):
        value = value.to_dict()
        value.pop("worst_violation")  # the core stops at the first bad state, Python at its chunk's end
        return "ok", tuple(sorted(value.items()))
    return "ok", tuple(np.ravel(value).tolist()) if isinstance(value, np.ndarray) else value


n = 7
NAN = np.full(n, np.nan)
SPACE_CASES = {
    # name: (method, argument(s) builder from (task, scene)), expecting an error or a verdict
    "states of the wrong width": ("violation", lambda t, s: (np.zeros((2, n + 1)),), "error"),
    "states of three dimensions": ("valid", lambda t, s: (np.zeros((2, 2, n)),), "error"),
    "projection of the wrong width": ("project", lambda t, s: (np.zeros((3, n - 1)),), "error"),
    "motion of the wrong width": ("valid_prefix", lambda t, s: (np.zeros((4, n + 2)), True), "error"),
    "NaN state": ("valid", lambda t, s: (np.stack([s.start, NAN]),), "ok"),
    "infinite state": ("valid", lambda t, s: (np.stack([np.full(n, np.inf), s.goal]),), "ok"),
    "state out of limits": ("valid", lambda t, s: (np.stack([s.start, t.robot.upper + 0.1]),), "ok"),
    "motion through NaN": ("valid_prefix", lambda t, s: (np.stack([s.start, NAN, s.start]), True), "ok"),
    "empty path": ("validate_path", lambda t, s: (np.zeros((0, n)),), "ok"),
    "path of the wrong width": ("validate_path", lambda t, s: (np.zeros((3, n + 1)),), "ok"),
    "path with NaN": ("validate_path", lambda t, s: (np.stack([s.start, NAN]),), "ok"),
    "path out of limits": ("validate_path", lambda t, s: (np.stack([s.start, t.robot.upper + 0.1]),), "ok"),
    "path into the wall": ("validate_path", lambda t, s: (np.stack([s.start, s.goal]),), "ok"),
}


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")  # numpy FK of inf states
@pytest.mark.parametrize("case", sorted(SPACE_CASES))
def test_the_native_space_refuses_what_the_python_space_refuses(problem, case):
    task, scene, space, fast, _ = problem
    method, arguments, expected = SPACE_CASES[case]
    python = _outcome(lambda: getattr(space, method)(*arguments(task, scene)))
    compiled = _outcome(lambda: getattr(fast, method)(*arguments(task, scene)))
    assert python[0] == expected and compiled == python, (python, compiled)
    if method == "valid_prefix" and expected == "ok":
        assert fast.stop == space.stop is not None  # stopped for the same reason
    if method == "validate_path" and expected == "ok":
        assert dict(python[1])["valid"] is False and dict(python[1])["reason"]


def _planner(task, scene, kind, core, **options):
    from manifoldgen.planning import RRTConnect, RRTConnectSettings
    from manifoldgen.specs import make_sampler
    y = options.pop("y", scene.condition)
    space = ConstrainedSpace(_constraint(task.robot, kind, **options), y, scene.checker(task.robot))
    return RRTConnect(space, make_sampler("project", space, 0), settings=RRTConnectSettings(core=core))


def _into_the_wall(task, scene) -> np.ndarray:
    """A configuration on the wall task's manifold, 30 % of the way from start to goal: the hand is in the wall."""
    q = scene.start + 0.3 * (scene.goal - scene.start)
    return ConstrainedSpace(task.constraint, scene.condition).project(q[None]).q[0]


QUERY_CASES = {
    "goal in collision": lambda t, s: (s.start, _into_the_wall(t, s), 1.0),
    "start of the wrong length": lambda t, s: (s.start[:-1], s.goal, 1.0),
    "NaN in the goal": lambda t, s: (s.start, NAN, 1.0),
    "start out of limits": lambda t, s: (t.robot.upper + 0.1, s.goal, 1.0),
    "goal off the manifold": lambda t, s: (s.start, np.zeros(n), 1.0),
    "no time": lambda t, s: (s.start, s.goal, 0.0),
    "NaN time": lambda t, s: (s.start, s.goal, float("nan")),
}


@pytest.mark.parametrize("kind", ["pose", "plane"])
@pytest.mark.parametrize("case", sorted(QUERY_CASES))
def test_a_native_search_refuses_what_the_python_search_refuses(panda_task, case, kind):
    from manifoldgen.scene import get_scene
    scene = get_scene(panda_task, "wall")
    outcomes = []
    for core in ("python", "native"):
        planner = _planner(panda_task, scene, kind, core)
        assert (planner.core is not None) == (core == "native")
        outcomes.append(_outcome(lambda: planner.solve(*QUERY_CASES[case](panda_task, scene))))
    assert outcomes[0][0] == "error" and outcomes[1] == outcomes[0], outcomes
    if case == "goal in collision":
        assert "goal configuration is in collision: panda_hand_0 with wall_left" in outcomes[0][1]


BUILD_CASES = {
    "unknown frame": dict(frame="panda_nowhere"),
    "condition of the wrong length": dict(y=[0.5, 0.5]),
    "NaN condition": dict(y=[np.nan]),
    "zero tolerance": {"pose": dict(position_tolerance=0.0), "plane": dict(tolerance=0.0)},
    "negative tolerance": {"pose": dict(orientation_tolerance=-0.01), "plane": dict(tolerance=-0.01)},
    "NaN tolerance": {"pose": dict(position_tolerance=np.nan), "plane": dict(tolerance=np.nan)},
}


@pytest.mark.parametrize("kind", ["pose", "plane"])
@pytest.mark.parametrize("case", sorted(BUILD_CASES))
def test_a_bad_constraint_or_condition_is_refused_alike_before_either_search(panda_task, case, kind):
    from manifoldgen.scene import get_scene
    scene = get_scene(panda_task, "wall")
    options = BUILD_CASES[case].get(kind, BUILD_CASES[case])  # per kind, or for both
    outcomes = [_outcome(lambda: _planner(panda_task, scene, kind, core, **options))
                for core in ("python", "native")]
    assert outcomes[0][0] == "error" and outcomes[1] == outcomes[0], outcomes


class Refusing(Constraint):
    """A Python constraint whose residual refuses configurations with a positive first joint."""

    def __init__(self, robot):
        self.robot = robot
        self.condition = Condition((), (), np.zeros((1, 0)))
        self.tolerance = np.full(1, 0.01)

    def residual(self, q, y):
        q, _ = self.batch(q, y)
        if np.any(np.asarray(q)[:, 0] > 0):
            raise ManifoldgenError("first joint must be <= 0 for this constraint; choose another state")
        return q[:, :1] * 0


def test_an_error_raised_inside_a_python_constraint_reaches_the_caller_unchanged(panda_task):
    space = ConstrainedSpace(Refusing(panda_task.robot), [])
    fast = native.NativeSpace(space, native.core_space(space))
    q = np.zeros((3, n))
    q[2, 0] = 0.5
    for call in ("violation", "valid"):
        outcomes = [_outcome(lambda: getattr(s, call)(q)) for s in (space, fast)]
        assert outcomes[0][0] == "error" and outcomes[1] == outcomes[0], outcomes
    assert np.array_equal(fast.valid(q[:2]), space.valid(q[:2]))  # and the core still works after it


# ------------------------------------------------------------------ a robot whose mesh cannot be sphere-fitted
TINY_URDF = """<?xml version="1.0"?>
<robot name="tiny">
  <link name="base"><collision><origin xyz="0 0 -0.1"/><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="l1"><collision><origin xyz="0.1 0 0"/><geometry><box size="0.2 0.04 0.04"/></geometry></collision></link>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.2 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="l2"><collision><geometry><mesh filename="MESH"/></geometry></collision>
    <collision><origin xyz="0.075 0 0"/><geometry><box size="0.15 0.03 0.03"/></geometry></collision></link>
  <joint name="tip_joint" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0.15 0 0"/></joint>
  <link name="tip"/>
</robot>
"""


def _stl(path, triangles):
    """A binary STL of ``triangles`` (T, 3, 3)."""
    import struct
    with open(path, "wb") as f:
        f.write(b"\0" * 80 + struct.pack("<I", len(triangles)))
        for t in triangles:
            f.write(struct.pack("<12f", 0, 0, 0, *np.ravel(t)) + b"\0\0")


def test_a_mesh_that_cannot_be_sphere_fitted_falls_back_to_exact_checks_and_says_so(tmp_path):
    from manifoldgen import spheres
    from manifoldgen.collision import CollisionChecker
    from manifoldgen.planning import RRTConnect, RRTConnectSettings
    from manifoldgen.robot import Robot
    from manifoldgen.shapes import Obstacle, Pose
    from manifoldgen.space import densify
    from manifoldgen.specs import make_sampler
    # l2's mesh has a vertex at NaN (a broken export): coal loads it, no sphere can cover it; l2's box stays
    bar = [[(0, -0.02, 0), (0.15, -0.02, 0), (0.15, 0.02, 0)], [(0, -0.02, 0), (0.15, 0.02, 0), (np.nan, 0.02, 0)]]
    _stl(tmp_path / "bar.stl", bar)
    (tmp_path / "tiny.urdf").write_text(TINY_URDF.replace("MESH", str(tmp_path / "bar.stl")))
    robot = Robot.load(str(tmp_path / "tiny.urdf"))
    model = spheres.fit_model(robot.collision_model)
    assert model.unfitted == (2,) and model.reasons == ("its mesh has non-finite vertex coordinates",)
    assert set(model.geometry.tolist()) == {0, 1, 3}  # the boxes keep their spheres
    post = Obstacle("post", "box", Pose([0.3, 0.0, 0.1]), size=[0.05, 0.05, 0.3])
    space = ConstrainedSpace(PoseConstraint(robot, "tip", np.eye(3), [[0.1]], orientation_axes=()), [0.1],
                             CollisionChecker(robot, obstacles=[post.geometry_object()]))
    with pytest.warns(UserWarning, match=r"sphere models: l2_0 has none \(its mesh has non-finite vertex "
                                         r"coordinates\); coal checks its pairs exactly"):
        planner = RRTConnect(space, make_sampler("project", space, 0), seed=0,
                             settings=RRTConnectSettings(core="native", spheres=True))
    start, goal = np.array([-1.2, 0.3]), np.array([1.2, -0.3])
    assert space.checker.in_collision(densify(np.stack([start, goal]), 0.01)[0]).any()  # the post is in the way
    result = planner.solve(start, goal, 20.0)
    assert result.solved and result.extras["core"] == "native" and result.extras["sphere_checks"] > 0
    assert result.extras["sphere_fallback"] == {"l2_0": "its mesh has non-finite vertex coordinates"}
    assert space.validate_path(result.path).valid
    assert not space.checker.in_collision(densify(result.path, space.settings.resolution)[0]).any()
