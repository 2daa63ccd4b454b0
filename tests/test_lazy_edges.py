"""Edge checks in the compiled core's search (RRTConnectSettings.edges). Coarse (``coarse:K``): returned paths
are checked at every planning-resolution state and densely, colliding edges found on candidate paths are cut,
``coarse:1`` checks every state at once, and a bad value is refused in one line. Dense (``dense:K``): every
motion passes the path check when it is made, so no candidate path is rejected and no edge cut."""

import numpy as np
import pytest

from manifoldgen.errors import ManifoldgenError
from manifoldgen.space import ConstrainedSpace, densify

pytest.importorskip("manifoldgen_core", reason="the compiled core is not built (scripts/setup.sh builds it)")


def _solve(task, scene_name: str, seed: int, stride: int, dense_edges: bool = False):
    """(space, result) of the core's RRT-Connect with the shipped CVAE, edges ``coarse:stride`` (or dense)."""
    from manifoldgen.models import pretrained_model_dir
    from manifoldgen.planning import RRTConnect, RRTConnectSettings
    from manifoldgen.scene import get_scene
    from manifoldgen.specs import make_sampler
    scene = get_scene(task, scene_name)
    space = ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))
    planner = RRTConnect(space, make_sampler(f"cvae:{pretrained_model_dir()}", space, seed), seed=seed,
                         settings=RRTConnectSettings(core="native", edges=f"{'dense' if dense_edges else 'coarse'}:{stride}"))
    return space, planner.solve(scene.start, scene.goal, 20.0)


def _assert_checked_state_by_state(task, space, path):
    """Every planning-resolution state of every edge (and every dense state) valid, checked in Python."""
    from manifoldgen.planning import RRTConnectSettings
    assert space.validate_path(path).valid
    for a, b in zip(path[:-1], path[1:]):
        states = densify(np.array([a, b]), RRTConnectSettings().resolution)[0]
        assert task.robot.within_limits(states).all()
        assert task.constraint.violation(states, space.y).max() <= 1.0
        assert not space.checker.in_collision(states).any()


def test_coarse_edges_that_collide_are_cut_and_paths_stay_checked(panda_task):
    """Stride 4 in the maze: trees grow through walls between coarse states, the candidate paths' edges are
    verified, the colliding ones cut, and the path returned is valid at every state."""
    space, result = _solve(panda_task, "maze", 90, 4)
    assert result.solved and result.extras["core"] == "native"
    assert result.extras["cut_edges"] > 0 and result.extras["verified_states"] > 0
    _assert_checked_state_by_state(panda_task, space, result.path)


@pytest.mark.parametrize("seed", [0, 1])
def test_stride_one_checks_every_state_at_once_and_coarse_checks_keep_the_search(panda_task, seed):
    """On the wall no coarse pass misses a collision: stride 2 makes the same path as stride 1 with fewer
    collision checks; stride 1 leaves nothing to verify."""
    eager_space, eager = _solve(panda_task, "wall", seed, 1)
    coarse_space, coarse = _solve(panda_task, "wall", seed, 2)
    assert eager.solved and coarse.solved
    assert eager.extras["verified_states"] == 0 and eager.extras["cut_edges"] == 0
    assert coarse.extras["verified_states"] > 0
    np.testing.assert_array_equal(eager.path, coarse.path)
    assert coarse.extras["collision_checks"] < eager.extras["collision_checks"]
    _assert_checked_state_by_state(panda_task, coarse_space, coarse.path)


def test_a_bad_edges_value_is_refused_in_one_line(panda_task):
    from manifoldgen.planning import RRTConnectSettings
    from manifoldgen.planning import planner_settings
    from manifoldgen.settings import check_settings
    for bad in ("coarse:0", "coarse:-2", "coarse:1.5", "dense", "lazy:2", "2", True):
        with pytest.raises(ManifoldgenError, match="edges must be 'coarse:K' or 'dense:K'") as error:
            RRTConnectSettings(edges=bad).check()
        assert "\n" not in str(error.value)
    with pytest.raises(ManifoldgenError, match="edges must be a string"):  # a task file's [planner] table
        check_settings({"edges": 2}, planner_settings("rrtconnect"), "planner")


def test_a_cut_edge_gives_its_node_another_parent(panda_task):
    """Coarse checks (every 2nd state, the default) in the maze, seed 36: an edge on a candidate path is cut and
    its node reattached to another parent instead of leaving with its subtree; the path returned is valid at
    every state."""
    space, result = _solve(panda_task, "maze", 36, 2)
    assert result.solved and result.extras["cut_edges"] > 0 and result.extras["reattached"] > 0
    _assert_checked_state_by_state(panda_task, space, result.path)


@pytest.mark.parametrize("scene_name", ["maze", "wall"])
def test_dense_edges_pass_the_path_check_as_they_are_made(panda_task, scene_name):
    """Stride 4 with dense edges, where coarse checks alone grow the trees through the maze's walls (the test
    above): every motion is path-checked when made, so no edge is cut, no candidate path rejected, and each edge
    of the path returned passes the Python space's path check on its own, state by state."""
    space, result = _solve(panda_task, scene_name, 90, 4, dense_edges=True)
    assert result.solved and result.extras["core"] == "native"
    assert result.extras["cut_edges"] == 0 and result.extras["rejected_paths"] == 0
    assert result.extras["verified_states"] == 0
    for a, b in zip(result.path[:-1], result.path[1:]):
        assert space.validate_path(np.array([a, b])).valid
    _assert_checked_state_by_state(panda_task, space, result.path)
