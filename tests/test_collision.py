"""Self-collision: SRDF pairs, known colliding configurations, the sampled matrix cache."""

import json

import numpy as np

from manifoldgen.collision import CollisionChecker, cache_dir
from manifoldgen.tasks import get_task


def test_home_is_free_and_a_folded_arm_collides(panda_task):
    checker = CollisionChecker(panda_task.robot)
    assert not checker.in_collision(panda_task.home)[0]
    folded = np.array([0.0, 1.7, 0.0, -3.0, 0.0, 0.5, 0.0])  # forearm driven into the base
    assert checker.in_collision(folded)[0]
    names = {name for pair in checker.collisions(folded) for name in pair}
    assert any(name.startswith("panda_link0") or name.startswith("panda_link1") for name in names)


def test_srdf_disabled_and_rigidly_attached_pairs_are_not_checked(panda_task):
    checker = CollisionChecker(panda_task.robot)
    objects = checker.geom.geometryObjects
    checked = {frozenset((objects[a].name, objects[b].name)) for a, b in checker.self_pairs}
    assert frozenset(("panda_hand_0", "panda_link7_0")) not in checked  # adjacent (SRDF)
    assert frozenset(("panda_leftfinger_0", "panda_hand_0")) not in checked  # locked fingers: rigid
    assert frozenset(("panda_link0_0", "panda_link5_0")) in checked


def test_centauro_matrix_is_sampled_once_and_cached(monkeypatch, private_cache):
    import manifoldgen.collision as collision

    task = get_task("pose", "centauro")
    before = set((cache_dir() / "collision").glob("centauro-*.json"))
    first = CollisionChecker(task.robot)  # its SRDF disables no pair: the matrix is sampled
    assert len(set((cache_dir() / "collision").glob("centauro-*.json")) - before) == 1
    assert any(json.loads(f.read_text())["pairs"] == [list(p) for p in first.self_pairs]
               for f in (cache_dir() / "collision").glob("centauro-*.json"))
    total = len(task.robot.collision_model.geometryObjects)
    assert 0 < len(first.self_pairs) < total * (total - 1) / 2
    monkeypatch.setattr(collision, "MATRIX_SAMPLES", collision.MATRIX_SAMPLES)  # same key
    monkeypatch.setattr(collision.pin, "computeCollisions", None)  # sampling again would fail
    again = collision._self_pairs(task.robot)
    assert again == first.self_pairs
