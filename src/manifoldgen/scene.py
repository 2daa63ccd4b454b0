"""Scenes: obstacles, a tool held by the robot, and one planning query (start, goal, y).

The obstacles and the held tool are :mod:`manifoldgen.shapes`. A scene is written to
and read from JSON; :meth:`Scene.to_meta` gives the obstacle list stored in path files,
enough for an outside checker with pinocchio and coal alone. Named scenes are the JSON files
a task file lists (``wall`` and ``maze`` for the panda pose task, ``wall`` for pr2);
:func:`task_anchors` gathers the starts and goals of a task's scenes.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from manifoldgen.collision import CollisionChecker
from manifoldgen.coverage import Anchors
from manifoldgen.errors import ManifoldgenError, check_keys, file_reader, not_a_file
from manifoldgen.io import atomic_write_text, read_json
from manifoldgen.robot import Robot
from manifoldgen.shapes import Attached, Obstacle, float_list, held_checker
from manifoldgen.targets import parse_target, resolve_query
from manifoldgen.tasks import Task

FORMAT_VERSION = 1
SCENE_KEYS = ("format_version", "name", "robot", "obstacles", "attached", "start", "goal", "condition")


@dataclass
class Scene:
    """Obstacles (world poses), an optional held tool, and a query: start, goal (n,) at condition y (k,).

    start and goal may be end-effector targets (dicts, see :mod:`manifoldgen.targets`) until
    :func:`get_scene` turns them into configurations; ``targets`` keeps the targets given."""

    name: str
    obstacles: list[Obstacle]
    attached: Attached | None
    start: np.ndarray | dict
    goal: np.ndarray | dict
    condition: np.ndarray
    robot: str = ""
    targets: dict = field(default_factory=dict)

    def checker(self, robot: Robot) -> CollisionChecker:
        """Self, robot-scene and tool collisions for ``robot``."""
        return held_checker(robot, self.attached, [o.geometry_object() for o in self.obstacles])

    def to_meta(self, robot: Robot | None = None) -> list[dict]:
        """JSON-ready objects: obstacles with world ``pose``; the tool last, with ``attached_to``
        (its frame), ``pose`` relative to that frame and ``touch_links`` (given ``robot``)."""
        out = [o.to_dict() for o in self.obstacles]
        if self.attached is not None:
            tool = self.attached.to_dict()
            if robot is not None:
                tool["touch_links"] = self.attached.resolved_touch_links(robot)
                tool["parent_joint"] = robot.model.names[robot.model.frames[robot.frame_id(self.attached.frame)]
                                                         .parentJoint]
            out.append(tool)
        return out

    @classmethod
    @file_reader
    def from_meta(cls, meta: dict) -> Scene:
        """The scene a path file records (the inverse of :meth:`to_meta`): obstacles, held tool, and the
        query's start, goal and condition."""
        items = meta.get("scene") or []
        obstacles = [Obstacle.from_dict(o, i) for i, o in enumerate(items) if "attached_to" not in o]
        tools = [Attached.from_dict(o) for o in items if "attached_to" in o]
        return cls(str(meta.get("scene_name", "")), obstacles, tools[0] if tools else None,
                   np.asarray(meta.get("start", []), float), np.asarray(meta.get("goal", []), float),
                   np.asarray(meta.get("condition", []), float), str(meta.get("robot", "")))

    def to_document(self, targets: bool = True) -> dict:
        """The scene file's JSON object; start and goal as the targets given (``targets``) or as configurations."""
        ends = {k: self.targets[k] if targets and k in self.targets else
                getattr(self, k) if isinstance(getattr(self, k), dict) else  # a target not solved yet
                np.asarray(getattr(self, k), float).tolist() for k in ("start", "goal")}
        return {"format_version": FORMAT_VERSION, "name": self.name, "robot": self.robot,
                "obstacles": [o.to_dict() for o in self.obstacles],
                "attached": None if self.attached is None else self.attached.to_dict(),
                **ends, "condition": np.asarray(self.condition, float).tolist()}

    def to_json(self) -> str:
        return json.dumps(self.to_document(), indent=1)

    def save(self, path: str | Path) -> None:
        atomic_write_text(Path(path), self.to_json())

    @classmethod
    def from_json(cls, text: str, source: str = "scene") -> Scene:
        try:
            data = read_json(text)
        except (ValueError, RecursionError) as exc:
            raise ManifoldgenError(f"{source} is not valid JSON ({exc}); fix the file") from exc
        if not isinstance(data, dict):
            raise ManifoldgenError(f"{source} must be a JSON object with 'obstacles', 'start', 'goal', 'condition'")
        check_keys(data, SCENE_KEYS, source)
        if data.get("format_version", FORMAT_VERSION) != FORMAT_VERSION:
            raise ManifoldgenError(f"{source}: format_version {data['format_version']!r} is not one this version reads "
                                   f"({FORMAT_VERSION}); write the scene in that format")
        missing = [k for k in ("obstacles", "start", "goal", "condition") if k not in data]
        if missing:
            raise ManifoldgenError(f"{source} lacks {', '.join(missing)}; a scene needs obstacles, start, goal "
                                   "and condition")
        if not isinstance(data["obstacles"], list):
            raise ManifoldgenError(f"{source}: 'obstacles' must be a list")
        obstacles = [Obstacle.from_dict(o, i) for i, o in enumerate(data["obstacles"])]
        seen = set()
        for obstacle in obstacles:
            if obstacle.name in seen:
                raise ManifoldgenError(f"{source}: obstacle name {obstacle.name!r} is given twice; give each obstacle "
                                       "a name of its own (a collision report names the obstacle hit)")
            seen.add(obstacle.name)
        attached = Attached.from_dict(data["attached"]) if data.get("attached") else None
        start, goal = (parse_target(data[k], f"{source} {k}") if isinstance(data[k], dict)
                       else float_list(data[k], f"{source} {k}") for k in ("start", "goal"))
        condition = float_list(data["condition"], f"{source} condition")
        for key in ("name", "robot"):
            if not isinstance(data.get(key, ""), str):
                raise ManifoldgenError(f"{source}: '{key}' must be a string, got {data[key]!r}")
        return cls(str(data.get("name", Path(source).stem)), obstacles, attached, start, goal, condition,
                   str(data.get("robot", "")))

    @classmethod
    @file_reader
    def load(cls, path: str | Path) -> Scene:
        path = Path(path)
        if not path.is_file():
            raise ManifoldgenError(not_a_file(path, "scene file"))
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError as exc:
            raise ManifoldgenError(f"scene file {path} is not UTF-8 text (byte {exc.start}); save it as UTF-8 "
                                   "JSON") from None
        return cls.from_json(text, str(path))


def task_checker(task: Task) -> CollisionChecker:
    """Self-collision and the object the task holds (its tray), with no scene: what collection checks."""
    return held_checker(task.robot, None if task.attached is None else Attached.from_dict(task.attached))


def get_scene(task: Task, name: str) -> Scene:
    """A scene the task file names (``wall``, ``maze``) or a scene JSON file for its robot."""
    if name in task.scenes:
        return _checked(Scene.load(task.scenes[name]), task, name)
    if not (name.endswith(".json") or Path(name).is_file()):
        known = ", ".join(task.scenes) or "none"
        raise ManifoldgenError(f"unknown scene '{name}' for task {task.name} on {task.robot.name}; named scenes: "
                               f"{known}; or give a path to a scene .json file")
    return _checked(Scene.load(name), task, name)


def _checked(scene: Scene, task: Task, name: str) -> Scene:
    """The scene, checked against the task, with end-effector targets turned into configurations."""
    n, k = task.robot.n, task.condition.k
    if scene.robot and scene.robot != task.robot.name:
        raise ManifoldgenError(f"scene {name} is for robot '{scene.robot}', not {task.robot.name}; give a scene for "
                               f"{task.robot.name}, or the task for {scene.robot}")
    for end in ("start", "goal"):
        value = getattr(scene, end)
        if not isinstance(value, dict) and value.shape != (n,):
            raise ManifoldgenError(f"scene {name}: {end} needs {n} joint values ({', '.join(task.robot.joints)}) or an "
                                   f"end-effector target {{\"position\": [x, y, z]}}, got {len(value)} values")
    if scene.condition.shape != (k,):
        raise ManifoldgenError(f"scene {name}: condition needs {k} value(s) ({', '.join(task.condition.names)}), "
                               f"got {len(scene.condition)}")
    if task.attached is not None:
        if scene.attached is not None:
            raise ManifoldgenError(f"scene {name} attaches '{scene.attached.shape.name}' but task {task.name} already "
                                   f"holds '{task.attached['name']}'; drop the scene's 'attached'")
        scene.attached = Attached.from_dict(task.attached)
    scene.targets = {end: getattr(scene, end) for end in ("start", "goal") if isinstance(getattr(scene, end), dict)}
    if scene.targets:
        scene.start, scene.goal = resolve_query(task.constraint, scene.condition, scene.start, scene.goal,
                                                scene.checker(task.robot), near=task.home)
    return scene


def task_anchors(task: Task) -> Anchors:
    """The start and goal of every scene of ``task`` (targets solved as ``plan`` solves them). A scene that
    cannot be set up is left out with a warning (``plan`` reports it in full); no scenes: no anchors."""
    qs, ys, labels, scenes = [], [], [], []
    for name in task.scenes:
        try:
            scene = get_scene(task, name)
        except ManifoldgenError as exc:
            warnings.warn(f"scene {name} left out of the query anchors: {exc}", stacklevel=2)
            continue
        for end in ("start", "goal"):
            qs.append(np.asarray(getattr(scene, end), float))
            ys.append(np.asarray(scene.condition, float))
            labels.append(f"{name} {end}")
        scenes.append(solved_document(scene, name))
    n, k = task.robot.n, task.condition.k
    return Anchors(np.array(qs, float).reshape(len(qs), n), np.array(ys, float).reshape(len(ys), k), labels, scenes)


def solved_document(scene: Scene, name: str) -> dict:
    """``scene`` as a scene document (what :meth:`Scene.from_json` reads) named ``name``, with its start and goal
    as the configurations they were solved to and the tool it holds: the query itself, with no target to solve."""
    return {**scene.to_document(targets=False), "name": name}
