"""Scenes: obstacle types, JSON round trip, named scenes' queries, the held tool, bad files."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from manifoldgen.collision import CollisionChecker, touch_links
from manifoldgen.errors import ManifoldgenError
from manifoldgen.scene import Scene, get_scene
from manifoldgen.shapes import Attached, Obstacle, Pose
from manifoldgen.tasks import builtin_tasks, get_task

BUILTIN_SCENES = Path(__file__).resolve().parents[1] / "src" / "manifoldgen" / "tasks" / "scenes"

NAMED = [(t, r, n) for t, robots in builtin_tasks().items() for r in robots for n in get_task(t, r).scenes]


@pytest.mark.slow
@pytest.mark.parametrize("task_name,robot,name", NAMED)
def test_named_scene_queries_are_valid(task_name, robot, name):
    task = get_task(task_name, robot)
    scene = get_scene(task, name)
    checker = scene.checker(task.robot)
    ends = np.stack([scene.start, scene.goal])
    assert task.constraint.satisfied(ends, scene.condition).all()
    assert task.constraint.violation(ends, scene.condition).max() < 1e-3
    assert not checker.in_collision(ends).any()
    assert scene.condition.tolist() in task.condition.values.tolist()  # PG datasets hold rows there
    assert scene.robot == robot
    if task.robot.floating_base:  # nothing is fixed to the world; the ends were checked against the obstacles above
        return
    # the robot parts fixed to the world (the base) are clear of every obstacle
    geom = task.robot.collision_model.copy()
    static = [i for i, g in enumerate(geom.geometryObjects) if g.parentJoint == 0]
    if task.robot.name == "point":  # the sphere task's point robot: no part fixed to the world
        return
    ids = [geom.addGeometryObject(o.geometry_object()) for o in scene.obstacles]
    for oid in ids:
        for i in static:
            geom.addCollisionPair(pin.CollisionPair(i, oid))
    data, gdata = task.robot.model.createData(), pin.GeometryData(geom)
    assert static and not pin.computeCollisions(task.robot.model, data, geom, gdata,
                                                task.robot.to_pinocchio(scene.start)[0], False)


def test_scene_ends_are_on_the_right_sides(panda_task):
    wall = get_scene(panda_task, "wall")
    p = panda_task.robot.frame_pose(np.stack([wall.start, wall.goal]), "panda_hand_tcp")[0]
    assert p[0, 1] > 0.27 and abs(p[1, 1]) < 0.2  # start outside the left wall, goal between the walls
    maze = get_scene(panda_task, "maze")
    p = panda_task.robot.frame_pose(np.stack([maze.start, maze.goal]), "panda_hand_tcp")[0]
    assert p[0, 1] > 0.1 and p[1, 1] < -0.1  # start in the left lane, goal in the right one


def test_json_round_trip_keeps_every_field(tmp_path, panda_task):
    mesh = str(next(panda_task.robot.collision_model.geometryObjects[1:2].__iter__()).meshPath)
    scene = get_scene(panda_task, "maze")
    scene.obstacles += [Obstacle("ball", "sphere", Pose([0.1, 0.6, 0.3]), radius=0.05),
                        Obstacle("post", "cylinder", Pose([-0.4, 0.4, 0.2], [0, 0, 0.38268343, 0.92387953]),
                                 radius=0.04, length=0.4),
                        Obstacle("part", "mesh", Pose([-0.5, -0.5, 0.1]), mesh=mesh, scale=0.5)]
    scene.save(tmp_path / "s.json")
    again = Scene.load(tmp_path / "s.json")
    assert json.loads(again.to_json()) == json.loads(scene.to_json())
    assert again.to_meta(panda_task.robot) == scene.to_meta(panda_task.robot)
    tool = again.to_meta(panda_task.robot)[-1]
    assert tool["attached_to"] == "panda_hand_tcp" and tool["size"] == [0.03, 0.03, 0.18]
    assert set(tool["touch_links"]) == {"panda_hand", "panda_leftfinger", "panda_rightfinger", "panda_link6",
                                        "panda_link7"}
    box = again.to_meta()[0]
    assert set(box) == {"name", "type", "pose", "size"} and len(box["pose"]["quaternion"]) == 4
    checker = again.checker(panda_task.robot)
    assert not checker.in_collision(np.stack([scene.start, scene.goal])).any()


def test_every_obstacle_type_collides_where_it_is(panda_task):
    robot = panda_task.robot
    p = robot.frame_pose(panda_task.home, "panda_link5")[0][0]  # inside the link5 mesh
    mesh = robot.collision_model.geometryObjects[3].meshPath
    shapes = [Obstacle("b", "box", Pose(p), size=[0.05, 0.05, 0.05]),
              Obstacle("s", "sphere", Pose(p), radius=0.03),
              Obstacle("c", "cylinder", Pose(p, [0.70710678, 0, 0, 0.70710678]), radius=0.02, length=0.1),
              Obstacle("m", "mesh", Pose(p), mesh=mesh, scale=[0.3, 0.3, 0.3])]
    for shape in shapes:
        here = CollisionChecker(robot, obstacles=[shape.geometry_object()])
        moved = Obstacle(shape.name, shape.type, Pose(p + [0, 0, 0.6]), size=shape.size, radius=shape.radius,
                         length=shape.length, mesh=shape.mesh, scale=shape.scale)
        away = CollisionChecker(robot, obstacles=[moved.geometry_object()])
        assert here.in_collision(panda_task.home)[0], shape.type
        assert not away.in_collision(panda_task.home)[0], shape.type
        assert any(shape.name in pair for pair in here.collisions(panda_task.home))


def test_held_tool_hits_obstacles_and_far_links_but_not_the_hand(panda_task):
    robot = panda_task.robot
    tcp = robot.frame_pose(panda_task.home, "panda_hand_tcp")[0][0]
    below = Obstacle("post", "box", Pose(tcp - [0, 0, 0.12]), size=[0.05, 0.05, 0.02])  # under the fingertips
    tool = Attached(Obstacle("tool", "box", Pose([0, 0, 0.06]), size=[0.03, 0.03, 0.18]), "panda_hand_tcp")
    bare = Scene("t", [below], None, panda_task.home, panda_task.home, np.array([0.45]))
    held = Scene("t", [below], tool, panda_task.home, panda_task.home, np.array([0.45]))
    assert not bare.checker(robot).in_collision(panda_task.home)[0]
    checker = held.checker(robot)
    assert checker.collisions(panda_task.home) == [("tool", "post")]
    pairs = {(checker.geom.geometryObjects[p.first].name, checker.geom.geometryObjects[p.second].name)
             for p in checker.geom.collisionPairs}
    assert ("panda_link4_0", "tool") in pairs and ("panda_hand_0", "tool") not in pairs
    assert touch_links(robot, robot.model.getJointId("panda_joint7")) == tool_links(held, robot)


def tool_links(scene, robot):
    return sorted(scene.attached.resolved_touch_links(robot))


def test_fast_batched_collisions_match_pair_by_pair(panda_task, rng):
    scene = get_scene(panda_task, "maze")
    checker = scene.checker(panda_task.robot)
    q = panda_task.robot.sample_uniform(300, rng)
    full = panda_task.robot.to_pinocchio(q)
    slow = [pin.computeCollisions(panda_task.robot.model, checker.data, checker.geom, checker.geom_data, row, True)
            for row in full]
    fast = checker.in_collision(q)
    np.testing.assert_array_equal(fast, slow)
    assert 0 < fast.mean() < 1
    assert checker.first_collision(q) == int(np.argmax(fast))
    assert checker.first_collision(q[~fast][:5]) == 5


@pytest.mark.parametrize("change,message", [
    ({"type": "cone"}, "unknown type 'cone'.*known types: box, sphere, cylinder, mesh"),
    ({"type": "boxx"}, "did you mean box"),
    ({"size": [0.1, -0.2, 0.3]}, "size .* must be three positive extents"),
    ({"size": [0.1, 0.2]}, "size \\(full extents x, y, z\\) must be 3 finite numbers"),
    ({"pose": {"position": [0, 0, 0], "quaternion": [0, 0, 0, 2]}}, "norm 2.0000; give a unit quaternion"),
    ({"pose": {"quaternion": [0, 0, 0, 1]}}, "pose needs 'position'"),
    ({"type": "sphere", "radius": 0}, "radius must be a positive number"),
    ({"type": "mesh", "mesh": "missing.stl"}, "mesh file 'missing.stl' not found"),
])
def test_bad_scene_files_say_what_is_wrong(tmp_path, panda_task, change, message):
    data = json.loads(get_scene(panda_task, "wall").to_json())
    data["obstacles"][0].update(change)
    if "pose" in change:
        data["obstacles"][0]["pose"] = change["pose"]
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ManifoldgenError, match=message):
        get_scene(panda_task, str(path))


def test_scene_lookup_errors(tmp_path, panda_task):
    with pytest.raises(ManifoldgenError, match="unknown scene 'mazee'.*named scenes: wall, maze"):
        get_scene(panda_task, "mazee")
    data = json.loads(get_scene(panda_task, "wall").to_json())
    (tmp_path / "short.json").write_text(json.dumps({**data, "start": [0.0, 0.1]}))
    with pytest.raises(ManifoldgenError, match="start needs 7 joint values .* or an end-effector target"):
        get_scene(panda_task, str(tmp_path / "short.json"))
    (tmp_path / "pr2.json").write_text(json.dumps({**data, "robot": "pr2"}))
    with pytest.raises(ManifoldgenError, match="is for robot 'pr2', not panda"):
        get_scene(panda_task, str(tmp_path / "pr2.json"))
    (tmp_path / "broken.json").write_text("{")
    with pytest.raises(ManifoldgenError, match="not valid JSON"):
        get_scene(panda_task, str(tmp_path / "broken.json"))
    assert set(NAMED) == {("pose", "panda", "wall"), ("pose", "panda", "maze"), ("pose", "pr2", "wall"),
                          ("balance", "centauro", "reach"), ("balance", "talos", "reach"), ("drinkcan", "centauro", "drinkcan"),
                          ("sphere", "point", "sphere"),
                          *(("dualarm", r, n) for r in ("pr2", "baxter") for n in ("tray-over", "tray-shelf"))}


@pytest.mark.parametrize("edit, needle", [
    (lambda d: d.update(obstacels=d.pop("obstacles")), "unknown key 'obstacels'; did you mean 'obstacles'?"),
    (lambda d: d["obstacles"][0].update(sise=[1, 1, 1]), "unknown key 'sise'; did you mean 'size'?"),
    (lambda d: d["obstacles"][0]["pose"].update(quaternoin=[0, 0, 0, 1]), "did you mean 'quaternion'?"),
    (lambda d: d.update(format_version=7), "format_version 7 is not one this version reads"),
])
def test_a_misspelt_key_or_unknown_version_is_refused_naming_the_nearest(edit, needle):
    data = json.loads((BUILTIN_SCENES / "panda-wall.json").read_text())
    edit(data)
    with pytest.raises(ManifoldgenError, match=re.escape(needle)):
        Scene.from_json(json.dumps(data), "wall.json")
