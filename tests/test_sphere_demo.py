"""OMPL's sphere demo as the task ``sphere``: the task and its scene are the demo's problem, a seeded plan is
valid state by state under the demo's own obstacle rule, and the C++ demo program (a benchmark extra, skipped
when not built) solves it, deterministically per seed, with paths that pass our dense check."""

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from manifoldgen.constraints import SphereConstraint
from manifoldgen.errors import ManifoldgenError
from manifoldgen.scene import get_scene
from manifoldgen.space import ConstrainedSpace, densify
from manifoldgen.tasks import get_task, task_from_spec

PROGRAM = Path(__file__).resolve().parents[1] / "benchmarks" / "ompl_native" / "build" / "sphere_demo"


def demo_free(x: np.ndarray) -> np.ndarray:
    """(B,) the demo's `obstacles` function (ConstrainedPlanningSphere.cpp) for points ``x (B, 3)``."""
    z, free = x[:, 2], np.ones(len(x), bool)
    for low, high, opening in ((-0.8, -0.6, (np.abs(x[:, 1]) < 0.05) & (x[:, 0] > 0)),
                               (-0.1, 0.1, (np.abs(x[:, 0]) < 0.05) & (x[:, 1] < 0)),
                               (0.6, 0.8, (np.abs(x[:, 1]) < 0.05) & (x[:, 0] < 0))):
        band = (low < z) & (z < high)
        free[band] = opening[band]
    return free


@pytest.fixture(scope="module")
def sphere():
    task = get_task("sphere")
    scene = get_scene(task, "sphere")
    return task, scene, ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))


def test_task_is_a_point_on_a_sphere_and_rebuilds_from_its_spec(sphere):
    task, scene, _ = sphere
    assert get_task("sphere", "point").file == task.file  # a package URDF robot is known by its name
    assert task.robot.joints == ["x", "y", "z"] and task.robot.n == 3
    np.testing.assert_array_equal(task.robot.lower, -2.0)
    np.testing.assert_array_equal(task.robot.upper, 2.0)
    assert task.condition.low[0] == 0.8 and task.condition.high[0] == 1.2
    np.testing.assert_array_equal(scene.start, [0, 0, -1])
    np.testing.assert_array_equal(scene.goal, [0, 0, 1])
    assert scene.condition.tolist() == [1.0]
    q = np.random.default_rng(0).uniform(-2, 2, (50, 3))
    np.testing.assert_allclose(task.constraint.residual(q, [1.1])[:, 0], np.linalg.norm(q, axis=1) - 1.1, atol=1e-12)
    rebuilt = task_from_spec(json.loads(json.dumps(task.spec())))
    assert rebuilt.spec() == task.spec()


def test_scene_boxes_are_the_demo_obstacles(sphere):
    task, scene, space = sphere
    rng = np.random.default_rng(1)
    on_sphere = rng.normal(size=(4000, 3))
    on_sphere /= np.linalg.norm(on_sphere, axis=1, keepdims=True)
    x = np.concatenate([rng.uniform(-1.3, 1.3, (4000, 3)), on_sphere,
                        rng.uniform([-0.1, -0.1, -1.0], [0.1, 0.1, 1.0], (4000, 3))])  # around the openings
    free = ~scene.checker(task.robot).in_collision(x)
    np.testing.assert_array_equal(free, demo_free(x))
    assert 0.02 < 1 - free[-4000:].mean() < 0.98  # the openings' neighbourhood holds both


def test_bad_sphere_parameters_are_one_line(sphere):
    robot = sphere[0].robot
    for kwargs, word in (({"values": [[-1.0]]}, "positive"), ({"values": [[1.0]], "center": [0, 0]}, "center"),
                         ({"values": [[1.0]], "tolerance": 0.0}, "tolerance")):
        with pytest.raises(ManifoldgenError, match=word) as exc:
            SphereConstraint(robot, "point", **kwargs)
        assert "\n" not in str(exc.value)


def test_seeded_plan_is_valid_state_by_state(sphere):
    from manifoldgen.planning import PLANNERS
    from manifoldgen.specs import make_sampler

    task, scene, space = sphere
    planner = PLANNERS.get("rrtconnect")(space, make_sampler("project", space, 0), seed=0)
    result = planner.solve(scene.start, scene.goal, 60.0)
    assert result.solved
    path = result.path
    np.testing.assert_array_equal(path[0], scene.start)
    np.testing.assert_array_equal(path[-1], scene.goal)
    states, _ = densify(path, 0.005)
    assert np.abs(np.linalg.norm(states, axis=1) - 1.0).max() <= 0.01  # the task's tolerance
    assert demo_free(states).all() and np.all(np.abs(states) <= 2.0)


needs_program = pytest.mark.skipif(not PROGRAM.is_file(), reason="the sphere demo program is not built "
                                   "(apt-get install libompl-dev; benchmarks/ompl_native/build.sh)")


def _demo(*args: str) -> list[dict]:
    out = subprocess.run([str(PROGRAM), *args], capture_output=True, text=True, check=True, timeout=60).stdout
    return [json.loads(line) for line in out.splitlines()]


@needs_program
def test_cpp_demo_solves_each_seed_the_same_way():
    first = _demo("--space", "atlas", "--seeds", "0:2", "--time", "20")
    again = _demo("--space", "atlas", "--seeds", "1", "--time", "20")
    assert [r["solved"] for r in first] == [True, True] and again[0]["solved"]
    keys = ("length", "states", "function_calls", "jacobian_calls", "validity_checks", "vertices", "charts")
    assert {k: first[1][k] for k in keys} == {k: again[0][k] for k in keys}  # reseeded per run: same search
    for r in first:
        assert r["tolerance"] == 1e-4 and r["check_tolerance"] == 0.01 and r["dense_checks"] > r["states"]
        assert r["function_calls"] > 0 and r["jacobian_calls"] > 0 and r["samples"] > 0 and r["charts"] > 2


@needs_program
def test_cpp_demo_refuses_bad_options_in_one_line():
    done = subprocess.run([str(PROGRAM), "--space", "bogus"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and "unknown OMPL space 'bogus'" in done.stderr and done.stderr.count("\n") == 1
    done = subprocess.run([str(PROGRAM), "--time", "soon"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and "--time needs a number" in done.stderr
