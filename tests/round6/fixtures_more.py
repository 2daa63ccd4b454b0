"""The edited and hand-made inputs of the round-6 table (called by fixtures.py once the base files are in ``root``):
edited path, dataset, model, roadmap and bench copies, task files, user constraint modules, scenes, configs."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np

from manifoldgen.io import load_npz
from manifoldgen.tasks import BUILTIN_DIR
from refusals import edited_npz, reseal, set_key

VALUES = "values = [[0.2], [0.3], [0.4], [0.5], [0.6], [0.7]]"
PLANNER = 'home_condition = [0.45]\n[planner]\n'
# a task of the panda's arm, before its constraint's type and fields
HEAD = ('name = "t"\nrobot = "panda"\ngroup = ["panda_joint1", "panda_joint2", "panda_joint3", "panda_joint4", '
        '"panda_joint5", "panda_joint6", "panda_joint7"]\n[[constraints]]\n')
TASKS = {  # name: the replacements made in the built-in pose task's text
    "type-capital": {'type = "pose"': 'type = "Pose"'},
    "locked-in-group": {"home_condition = [0.45]": "home_condition = [0.45]\n[locked]\npanda_joint1 = 0.0"},
    "locked-outside": {"home_condition = [0.45]": "home_condition = [0.45]\n[locked]\npanda_finger_joint1 = 5.0"},
    "group-dup": {'"panda_joint7"]': '"panda_joint7", "panda_joint1"]'},
    "group-empty": {'group = ["panda_joint1", "panda_joint2", "panda_joint3", "panda_joint4", "panda_joint5", '
                    '"panda_joint6",\n         "panda_joint7"]': "group = []"},
    "group-fixed": {'"panda_joint7"]': '"panda_joint7", "panda_hand_joint"]'},
    "scene-missing": {"maze = ": 'gone = "nope.json"\nmaze = '},
    "robot-passwd": {'robot = "panda" ': 'robot = "PASSWD" '},  # /etc/passwd relative to the task file
    "values-1e308": {VALUES: "values = [[1e308], [0.5]]"},
    "values-int-huge": {VALUES: "values = [[9223372036854775807], [0.5]]"},
    "tol-str": {'position_axes = ["z"]': 'position_axes = ["z"]\norientation_tolerance = "0.01"'},
    "tol-bool": {'position_axes = ["z"]': 'position_axes = ["z"]\nposition_tolerance = true'},
    "planner-misspelt": {"home_condition = [0.45]": PLANNER + "rnage = 0.5"},
    "planner-range-neg": {"home_condition = [0.45]": PLANNER + "range = -1.0"},
    "planner-edges-bad": {"home_condition = [0.45]": PLANNER + 'edges = "coarse:-3"'},
    "dup-key": {"home_condition = [0.45]": "home_condition = [0.45]\nhome_condition = [0.5]"},
    "name-unicode": {'name = "pose"': 'name = "pösé ✓ 名前"'},
    "axes-w": {'position_axes = ["z"]': 'position_axes = ["w"]'},
    "axes-string": {'position_axes = ["z"]': 'position_axes = "xz"'},
    "frame-unknown": {'frame = "panda_hand_tcp"': 'frame = "panda_hand_tpc"'},
    "builtin-only": {},
    "bounds-reversed": {'robot = "panda" ': 'robot = "panda"\nfloating_base = true\n'
                                           'base_bounds = [[1.0, 1.0, 1.0], [-1.0, -1.0, -1.0]]\n'},
    "bounds-nan": {'robot = "panda" ': 'robot = "panda"\nfloating_base = true\n'
                                      'base_bounds = [[nan, -1.0, -1.0], [1.0, 1.0, 1.0]]\n'},
}
JOINT = ('<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/><axis xyz="0 0 1"/>'
         '<limit lower="-1" upper="1" effort="1" velocity="{velocity}"/></joint>')
URDFS = {
    "xxe": '<?xml version="1.0"?>\n<!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/hostname">]>\n'
           '<robot name="xxe"><link name="base"/><link name="l1"/>\n'
           + JOINT.format(name="j&x;", parent="base", child="l1", velocity=1) + "</robot>\n",
    "missing-mesh": '<robot name="mm"><link name="base"><collision><geometry>'
                    '<mesh filename="package://nowhere/x.stl"/></geometry></collision></link><link name="l1"/>\n'
                    + JOINT.format(name="j1", parent="base", child="l1", velocity=1) + "</robot>\n",
    "vel-zero": '<robot name="vz"><link name="base"/><link name="l1"/><link name="l2"/>\n'
                + JOINT.format(name="j1", parent="base", child="l1", velocity=0)
                + JOINT.format(name="j2", parent="l1", child="l2", velocity=1) + "</robot>\n",
}
# a user constraint of the xarm7 (the tool's height, pointing down), with a line of its own in __init__ or residual
MODULE = '''import numpy as np, sys
from manifoldgen.constraints import Condition, Constraint, array_namespace


class Tool(Constraint):
    def __init__(self, robot, frame="link_eef"):
        self.robot, self.frame = robot, frame
        self.condition = Condition(("x",), ("m",), np.asarray([[0.3], [0.4], [0.5]], float))
        self.tolerance = np.full(3, 0.01)
        {init}

    def residual(self, q, y):
        q, y = self.batch(q, y)
        p, R = self.robot.frame_pose(q, self.frame)
        out = array_namespace(q).concat([p[:, :1] - y, R[:, :2, 2]], axis=1)
        {residual}
        return out
'''
MODULES = {"u_exit": ("sys.exit(0)", "pass"), "u_nan": ("pass", "out = out * float('nan')"),
           "u_recursion": ("pass", "return self.residual(q, y)"), "u_ok": ("pass", "pass"),
           "u_list": ("pass", "out = out.tolist() if isinstance(out, np.ndarray) else out"),
           "u_int": ("pass", "out = np.zeros((len(q), 3), dtype=np.int64) if isinstance(out, np.ndarray) else out"),
           "u_print": ("pass", "print('residual called', len(q))")}
FAR = {"position": [2, 2, 2], "quaternion": [0, 0, 0, 1]}
SCENES = {  # name: an edit of the panda's wall scene
    "start-in-wall": lambda d: d.update(start={"position": [0.55, 0.25, 0.3], "quaternion": [1.0, 0, 0, 0]}),
    "goal-outside-limits": lambda d: d.update(goal=[5.0] * 7),
    "cond-far": lambda d: d.update(condition=[5.0]),
    "obst-far": lambda d: d["obstacles"].append({"name": "x", "type": "box", "size": [0.1, 0.1, 0.1],
                                                 "pose": {"position": [1e308, 0, 0], "quaternion": [0, 0, 0, 1]}}),
    "box-neg": lambda d: d["obstacles"].append({"name": "x", "type": "box", "size": [-0.1, 0.1, 0.1], "pose": FAR}),
    "mesh-missing": lambda d: d["obstacles"].append({"name": "m", "type": "mesh", "mesh": "/nonexistent/x.stl",
                                                     "scale": [1, 1, 1], "pose": FAR}),
    "type-code": lambda d: d["obstacles"].append({"name": "m", "type": "evilmod:C", "pose": FAR}),
    "fmt-99": lambda d: d.update(format_version=99),
    "unknown-key": lambda d: d.update(obstacels=[]),
    "obst-not-list": lambda d: d.update(obstacles={"a": 1}),
    "bool-size": lambda d: d["obstacles"][0].update(size=[True, 0.04, 0.6]),
}


def task_text(**replace) -> str:
    """The built-in pose task's text (its scene paths made absolute) with each key replaced by its value."""
    text = (BUILTIN_DIR / "pose-panda.toml").read_text().replace('"scenes/', f'"{BUILTIN_DIR}/scenes/')
    for old, new in replace.items():
        assert old in text, old
        text = text.replace(old, new)
    return text


def model_copy(root: Path, name: str, edit=None, weights=None) -> None:
    shutil.copytree(root / "model", root / name)
    reseal(root / name, edit, weights)


def paths(root: Path) -> None:
    """Path files: stored as float32, the straight start-goal line, two joints swapped, an infinite time limit,
    another robot."""
    meta, _ = load_npz(root / "path.npz", ())
    start, goal = np.array(meta["start"]), np.array(meta["goal"])
    edited_npz(root / "path.npz", root / "p-f32.npz", arrays=lambda a: a.update(path=a["path"].astype(np.float32)))
    edited_npz(root / "path.npz", root / "p-direct.npz", set_key("result", "waypoints", value=2),
               lambda a: a.update(path=np.stack([start, goal])))

    def swap(m):
        m["joints"][:2] = m["joints"][1::-1]
        m["task"]["group"][:2] = m["task"]["group"][1::-1]
    edited_npz(root / "path.npz", root / "p-joints-swapped.npz", swap)
    edited_npz(root / "path.npz", root / "p-time-inf.npz", set_key("time_limit", value=float("inf")))
    edited_npz(root / "path.npz", root / "p-robot-talos.npz",
               lambda m: m.update(robot="talos") or m["task"]["robot"].update(name="talos"))


def datasets_models_roadmaps(root: Path) -> None:
    """A dataset cut in half, emptied, off its conditions, with five rows off its manifold; models whose files or
    fields were damaged (resealed); roadmaps of another format, another resolution, an edge to node -1, an edge
    from the node nearest the start to the one nearest the goal (through the wall)."""
    blob = (root / "data.npz").read_bytes()
    (root / "d-trunc.npz").write_bytes(blob[:len(blob) // 2])
    edited_npz(root / "data.npz", root / "d-zero-rows.npz", arrays=lambda a: a.update(q=a["q"][:0], y=a["y"][:0]))
    edited_npz(root / "data.npz", root / "d-y-off.npz", arrays=lambda a: a.update(y=np.full_like(a["y"], 5.0)))

    def off(a):
        a["q"] = a["q"].copy()
        a["q"][:5] = np.random.default_rng(0).uniform(-1, 1, a["q"][:5].shape)
    edited_npz(root / "data.npz", root / "d-offmanifold.npz", arrays=off)
    shutil.copytree(root / "model", root / "m-noweights")
    (root / "m-noweights" / "model.safetensors").unlink()
    shutil.copytree(root / "model", root / "m-trunc-weights")
    weights = (root / "model" / "model.safetensors").read_bytes()
    (root / "m-trunc-weights" / "model.safetensors").write_bytes(weights[:100])
    (root / "m-jsondir" / "model.json").mkdir(parents=True)
    shutil.copy(root / "model" / "model.safetensors", root / "m-jsondir")
    model_copy(root, "m-qstd-zero", lambda d: d["normalisation"].update(q_std=[0.0] * len(d["normalisation"]["q_std"])))
    model_copy(root, "m-refine-huge", set_key("refine", value=10 ** 9))
    model_copy(root, "m-refine-neg", set_key("refine", value=-3))
    model_copy(root, "m-epochs-str", set_key("config", "epochs", value="many"))
    model_copy(root, "m-mix-neg", set_key("mix", value=-1))
    edited_npz(root / "rm.npz", root / "rm-fmt2.npz", set_key("format_version", value=2))
    edited_npz(root / "rm.npz", root / "rm-res-lie.npz", set_key("resolution", value=0.05))

    def negative_edge(a):
        a["edges"] = a["edges"].copy()
        a["edges"][0, 0] = -1
    edited_npz(root / "rm.npz", root / "rm-edge-neg.npz", arrays=negative_edge)
    meta, _ = load_npz(root / "path.npz", ())  # the wall's query: its start and goal

    def direct_edge(a):
        nearest = sorted(int(np.argmin(np.linalg.norm(a["nodes"] - meta[end], axis=1))) for end in ("start", "goal"))
        a["edges"] = np.concatenate([a["edges"], [nearest]]).astype(a["edges"].dtype)
        a["lengths"] = np.append(a["lengths"], np.linalg.norm(np.subtract(*a["nodes"][nearest])))
    edited_npz(root / "rm.npz", root / "rm-direct-edge.npz", arrays=direct_edge)


def benches(root: Path) -> None:
    """Bench folders: run 0's recorded path replaced by the straight start-goal line; no run recorded."""
    meta, _ = load_npz(root / "path.npz", ())
    lines = (root / "bench" / "runs.jsonl").read_text().splitlines()
    record = json.loads(lines[0])
    record["path"] = [meta["start"], meta["goal"]]
    shutil.copytree(root / "bench", root / "b-rec-direct")
    (root / "b-rec-direct" / "runs.jsonl").write_text("\n".join([json.dumps(record)] + lines[1:]) + "\n")
    shutil.copytree(root / "bench", root / "b-empty-jsonl")
    (root / "b-empty-jsonl" / "runs.jsonl").write_text("")


def tasks_and_robots(root: Path) -> None:
    """Task files (the built-in pose task edited, constraints of the arm alone, a binary file), URDFs, and xarm7 user
    constraints beside their task files."""
    tasks = root / "tasks"
    tasks.mkdir()
    passwd = os.path.relpath("/etc/passwd", tasks)
    for name, replace in TASKS.items():
        (tasks / f"{name}.toml").write_text(task_text(**replace).replace("PASSWD", passwd))
    (tasks / "att-zero.toml").write_text(task_text() + '\n[attached]\nname = "cup"\ntype = "box"\n'
                                         'attached_to = "panda_hand_tcp"\nsize = [0.0, 0.0, 0.0]\n'
                                         'pose = { position = [0.0, 0.0, 0.1] }\n')
    (tasks / "stdlib-class.toml").write_text(HEAD + 'type = "json:JSONDecoder"\n')
    (tasks / "binary.toml").write_bytes(np.random.default_rng(0).bytes(300))
    for name, text in URDFS.items():
        (tasks / f"{name}.urdf").write_text(text)
    user = root / "user"
    user.mkdir()
    for name, (init, residual) in MODULES.items():
        (user / f"{name}.py").write_text(MODULE.format(init=init, residual=residual))
        (user / f"{name}.toml").write_text(
            f'name = "{name}"\nrobot = "xarm7"\ngroup = ["joint1", "joint2", "joint3", "joint4", "joint5", "joint6", '
            f'"joint7"]\n[[constraints]]\ntype = "{name}:Tool"\nframe = "link_eef"\n')
    (user / "class-missing.toml").write_text(HEAD + 'type = "u_ok:Nope"\n')
    (user / "no-class.toml").write_text(HEAD + 'type = "u_ok:"\n')


def scenes_and_configs(root: Path) -> None:
    """Scene files (the panda's wall edited, an empty object, a 5000-digit number, a mesh that is a dataset, a pr2
    scene), planner and model configs, and a page that is no input of view."""
    scenes = root / "scenes"
    scenes.mkdir()
    wall = json.loads((BUILTIN_DIR / "scenes" / "panda-wall.json").read_text())
    for name, edit in SCENES.items():
        scene = json.loads(json.dumps(wall))
        edit(scene)
        (scenes / f"{name}.json").write_text(json.dumps(scene))
    (scenes / "cube.stl").write_text("solid c\nendsolid c\n")
    for name, mesh, scale in (("mesh-npz", root / "data.npz", [1, 1, 1]),
                              ("scale-zero", scenes / "cube.stl", [0, 1, 1])):
        scene = json.loads(json.dumps(wall))
        scene["obstacles"].append({"name": "m", "type": "mesh", "mesh": str(mesh), "scale": scale, "pose": FAR})
        (scenes / f"{name}.json").write_text(json.dumps(scene))
    (scenes / "empty-object.json").write_text("{}")
    (scenes / "huge-int.json").write_text(json.dumps(wall).replace('"format_version": 1',
                                                                   '"format_version": ' + "9" * 5000))
    shutil.copy(BUILTIN_DIR / "scenes" / "pr2-tray-over.json", scenes / "pr2-tray-over.json")
    (root / "cfg-nested.toml").write_text("[cvae]\nlatent = 3\n")
    (root / "cfg-range-str.toml").write_text('range = "far"\n')
    (root / "cfg-bad.toml").write_text("range = = 3\n")
    (root / "cfg-ompl-nan.toml").write_text("ompl_range = nan\n")
    (root / "page.html").write_text("<!doctype html><html><body>a page view exported</body></html>\n")


def make(root: Path) -> None:
    paths(root)
    datasets_models_roadmaps(root)
    benches(root)
    tasks_and_robots(root)
    scenes_and_configs(root)
