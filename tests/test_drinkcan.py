"""The drinkcan task (the paper's real-robot experiment): its query is consistent, and the bench's CVAE can cover
its manifold."""

import re
from pathlib import Path

import numpy as np
import pytest

from manifoldgen.scene import get_scene
from manifoldgen.space import ConstrainedSpace
from manifoldgen.tasks import get_task

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_balance.sh"


@pytest.fixture(scope="module")
def drinkcan():
    task = get_task("drinkcan")
    return task, get_scene(task, "drinkcan")


def test_the_query_keeps_a_trained_condition_and_must_pass_the_wall(drinkcan):
    task, scene = drinkcan
    y = scene.condition
    assert y.tolist() in task.condition.grid.tolist()  # a trained wrist value, not an interpolated one
    space = ConstrainedSpace(task.constraint, y, scene.checker(task.robot))
    wall = next(o for o in scene.obstacles if o.name == "obstacle")
    near, far = wall.pose.position[1] - wall.size[1] / 2, wall.pose.position[1] + wall.size[1] / 2
    hands = {}
    for end, q in (("start", scene.start), ("goal", scene.goal)):
        assert space.problem(q) is None, end  # on the manifold, inside the limits, collision-free
        assert abs(q[task.robot.joints.index("j_arm1_6")] - y[0]) <= 0.01  # the wrist joint holds the condition
        position, rotation = task.robot.frame_pose(q[None], "arm1_8")
        assert rotation[0][2, 2] >= np.cos(0.015)  # the can upright
        np.testing.assert_allclose(position[0], scene.targets[end]["position"], atol=0.01)
        hands[end] = position[0]
    assert hands["start"][1] > far and hands["goal"][1] < near  # the can starts and ends on either side of the wall
    chord = scene.start + (scene.goal - scene.start) * np.linspace(0, 1, 101)[:, None]
    assert not space.valid(chord).all()  # no straight way across: the planner must find one


def test_the_manifold_is_4_dimensional_and_the_bench_cvae_has_a_latent_as_large(drinkcan):
    task, scene = drinkcan
    for q, y in ((task.home, task.home_condition), (scene.start, scene.condition), (scene.goal, scene.condition)):
        _, jacobian = task.constraint.jacobian(q[None], y[None])
        assert task.robot.n - np.linalg.matrix_rank(jacobian[0], tol=1e-6) == 4
    block = BENCH.read_text().split('if [[ " $steps " == *" drinkcan "* ]]; then', 1)[1]
    trains = re.findall(r"\btrain\b[^\n]*", block)
    assert len(trains) == 1 and "--model cvae" in trains[0]
    assert re.search(r"--set latent=(\d+)", trains[0]).group(1) == "4"  # the CVAE's default, 3, covers a 3-D sheet
