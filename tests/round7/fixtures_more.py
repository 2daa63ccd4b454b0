"""The edited and hand-made inputs of the round-7 table (called by fixtures.py once the base files are in ``root``):
task files of the panda's arm (tasks7/), user constraint modules beside theirs (user7/), edited wall scenes
(scenes7/), roadmaps, a path, a model and a bench folder edited, configs."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np

from manifoldgen.tasks import BUILTIN_DIR
from refusals import edited_npz, set_key
from round6.fixtures_more import model_copy

GROUP = ", ".join(f'"panda_joint{i}"' for i in range(1, 8))
HEAD = f'name = "p7"\nrobot = "panda"\ngroup = [{GROUP}]\n'
DOWN = "rotation = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]\n"
POSE = ('[[constraints]]\ntype = "pose"\nframe = "panda_hand_tcp"\n' + DOWN
        + 'position_axes = ["z"]\nvalues = [[0.4], [0.5]]\n')
HELD = ('[attached]\nname = "ball"\ntype = "sphere"\nradius = 0.03\nattached_to = "panda_hand_tcp"\n'
        'pose = {position = [0.0, 0.0, 0.06], quaternion = [0.0, 0.0, 0.0, 1.0]}\n')
TASKS = {  # name: the text below HEAD
    "second-pose-no-values": POSE + '[[constraints]]\ntype = "pose"\nframe = "panda_hand_tcp"\n'
                             'rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\nposition_axes = []\n',
    "pose-no-position-axes": POSE.replace('["z"]', "[]").replace("[[0.4], [0.5]]", "[[]]"),
    "pose-three-axes": POSE.replace('["z"]', '["x", "y", "z"]').replace("[[0.4], [0.5]]",
                                                                       "[[0.4, 0.0, 0.4], [0.5, 0.1, 0.4]]"),
    "pose-single-value": "home_condition = [0.45]\n" + POSE.replace("[[0.4], [0.5]]", "[[0.45]]"),
    "orientation-underflow": '[[constraints]]\ntype = "orientation"\nframe = "panda_hand_tcp"\n'
                             "direction = [1e-300, 0.0, 0.0]\n",
    "plane-three-normals": '[[constraints]]\ntype = "plane"\nframe = "panda_hand_tcp"\nnormals = [[1.0, 0.0, 0.0], '
                           "[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\nvalues = [[0.4, 0.0, 0.4]]\n",
    "plane-four-normals": '[[constraints]]\ntype = "plane"\nframe = "panda_hand_tcp"\nnormals = [[1.0, 0.0, 0.0], '
                          "[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 0.0]]\nvalues = [[0.4, 0.0, 0.4, 0.4]]\n",
    "sphere-unreachable": '[[constraints]]\ntype = "sphere"\nframe = "panda_hand_tcp"\ncenter = [100.0, 0.0, 0.0]\n'
                          "values = [[0.5]]\n",
    "joint-linear": '[[constraints]]\ntype = "joint_linear"\n'
                    "coefficients = [[1.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0]]\nvalues = [[0.0], [0.3]]\n",
    "joint-linear-denormal": '[[constraints]]\ntype = "joint_linear"\n'
                             "coefficients = [[1e-300, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]]\nvalues = [[0.0]]\n",
    "closed-chain-one-frame": '[[constraints]]\ntype = "closed_chain"\nframe_a = "panda_hand_tcp"\n'
                              'frame_b = "panda_hand_tcp"\nrotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], '
                              "[0.0, 0.0, 1.0]]\nvalues = [[0.3]]\n",
    "rotation-axis-zero": '[[constraints]]\ntype = "rotation"\nframe = "panda_hand_tcp"\n' + DOWN
                          + "axis = [0.0, 0.0, 0.0]\nvalues = [[0.0]]\n",
    "rotation-yaw": '[[constraints]]\ntype = "rotation"\nframe = "panda_hand_tcp"\n' + DOWN
                    + 'axis = [0.0, 0.0, 1.0]\nname = "yaw"\nvalues = [[0.0], [0.5]]\n',
    "planner-range-zero": POSE + "[planner]\nrange = 0.0\n",
    "planner-shortcut": POSE + f'[scenes]\nwall = "{BUILTIN_DIR}/scenes/panda-wall.json"\n[planner]\nshortcut = 30\n',
    "touch-link-misspelt": POSE + HELD + 'touch_links = ["panda_hnad"]\n',
    "locked-at-upper-limit": "[locked]\npanda_finger_joint1 = 0.04\n" + POSE,
    "home-at-joint-limit": "home = [2.8973, -0.785398, 0.0, -2.35619, 0.0, 1.5707, 0.785398]\n"
                           "home_condition = [0.45]\n" + POSE.replace("[[0.4], [0.5]]", "[[0.4], [0.45], [0.5]]"),
}
OTHER_TASKS = {  # name: the whole text
    "six-joints": HEAD.replace(', "panda_joint7"', "") + "[locked]\npanda_joint7 = 0.785398\n" + POSE,
    "pr2-frame-of-panda": HEAD.replace('"panda"', '"pr2"').replace(GROUP, '"r_shoulder_pan_joint"') + POSE,
}
# a user constraint of the panda's arm (the tool's height), with a line of its own in residual() and more methods
MODULE = '''import numpy as np
from manifoldgen.constraints import Condition, Constraint


class C(Constraint):
    def __init__(self, robot, frame="panda_hand_tcp", values=((0.4,), (0.5,)), tolerance=0.01):
        self.robot, self.frame = robot, frame
        self.condition = Condition(("z",), ("m",), np.asarray({values}, float))
        self.tolerance = np.full({components}, tolerance)

    def residual(self, q, y):
        q, y = self.batch(q, y)
        p, R = self.robot.frame_pose(q, self.frame)
        {residual}
{more}'''
HEIGHT = "return p[:, 2:3] - y"
MODULES = {  # module: (condition values, tolerance components, the end of residual(), more methods)
    "r7_two_tolerances": ("values", 2, HEIGHT, ""),
    "r7_memory": ("values", 1, "raise MemoryError('boom')", ""),
    "r7_flat_inequality": ("values", 1, HEIGHT, "\n    def inequality(self, q, y):\n        q, y = self.batch(q, y)\n"
                                                "        return q[:, 0] - 10.0\n"),
    "r7_flat_values": ("[0.4, 0.5]", 1, HEIGHT, ""),
    "r7_changes_q": ("values", 1, "r = p[:, 2:3] - y\n        if isinstance(q, np.ndarray):\n"
                                  "            q[:, 0] = 0.0\n        return r", ""),
    "r7_height": ("values", 1, HEIGHT, ""),
}
DOWNWARD = [1.0, 0.0, 0.0, 0.0]
SCENES = {  # name: an edit of the panda's wall scene
    "swallowed": lambda d: d["obstacles"].append({"name": "blob", "type": "sphere", "radius": 5.0,
                                                  "pose": {"position": [0, 0, 0], "quaternion": [0, 0, 0, 1]}}),
    "beside-the-wall": lambda d: d.update(condition=[0.5], start={"position": [0.4, 0.3, 0.5], "quaternion": DOWNWARD},
                                          goal={"position": [0.4, -0.3, 0.5], "quaternion": DOWNWARD}),
    "goal-target": lambda d: d.update(goal={"position": [0.3, 0.0, 0.5], "quaternion": DOWNWARD}),
    "no-obstacles": lambda d: d.update(obstacles=[]),
    "held-sphere": lambda d: d.update(attached={"name": "ball", "type": "sphere", "radius": 0.03,
                                                "attached_to": "panda_hand_tcp",
                                                "pose": {"position": [0, 0, 0.06], "quaternion": [0, 0, 0, 1]}}),
}
EVIL = {"type": "evilmod:C"}  # a user type whose module is on the path of the case (tests/test_hostile_round7_table)


def tasks(root: Path) -> None:
    """Task files of the panda's arm (and one of the pr2, two of talos' balance with a margin edited), one in a
    subfolder naming its scene relative to it."""
    folder = root / "tasks7"
    (folder / "sub").mkdir(parents=True)
    for name, text in TASKS.items():
        (folder / f"{name}.toml").write_text(HEAD + text)
    for name, text in OTHER_TASKS.items():
        (folder / f"{name}.toml").write_text(text)
    (folder / "sub" / "scene-relative.toml").write_text(HEAD + POSE + '[scenes]\nwall = "../../wall.json"\n')
    balance = (BUILTIN_DIR / "balance-talos.toml").read_text().replace('"scenes/', f'"{BUILTIN_DIR}/scenes/')
    for name, margin in (("margin-huge", "1.0"), ("margin-negative", "-0.05")):
        (folder / f"{name}.toml").write_text(balance.replace("margin = 0.02", f"margin = {margin}"))


def user_modules(root: Path) -> None:
    """User constraint modules, each with its task file beside it, and one that does not subclass Constraint."""
    folder = root / "user7"
    folder.mkdir()
    for name, (values, components, residual, more) in MODULES.items():
        (folder / f"{name}.py").write_text(MODULE.format(values=values, components=components, residual=residual,
                                                         more=more))
    duck = MODULE.format(values="values", components=1, residual=HEIGHT, more="")
    (folder / "r7_duck.py").write_text(duck.replace("class C(Constraint)", "class C").replace(
        "q, y = self.batch(q, y)", "q, y = np.atleast_2d(q), np.atleast_2d(y)"))
    for name in [*MODULES, "r7_duck"]:
        (folder / f"{name}.toml").write_text(HEAD + f'[[constraints]]\ntype = "{name}:C"\nvalues = [[0.4], [0.5]]\n')


def scenes(root: Path) -> None:
    """The wall scene edited; one ending in a trailing comma, one behind a byte-order mark."""
    folder = root / "scenes7"
    folder.mkdir()
    text = (root / "wall.json").read_text()
    for name, edit in SCENES.items():
        scene = json.loads(text)
        edit(scene)
        (folder / f"{name}.json").write_text(json.dumps(scene))
    (folder / "trailing-comma.json").write_text(text.rstrip().rstrip("}").rstrip() + ",\n}")
    (folder / "bom.json").write_bytes(b"\xef\xbb\xbf" + text.encode())


def edited(root: Path) -> None:
    """Roadmaps (edges reversed, lengths off by 1e-8 and by 1e-11, a node alone at zero, a user type), a path and a
    model naming a user type, a bench folder with a run of a method it does not list, configs."""
    rm = root / "rm.npz"
    edited_npz(rm, root / "rm-reversed.npz", arrays=lambda a: a.update(edges=a["edges"][:, ::-1].copy()))
    edited_npz(rm, root / "rm-length-1e-8.npz", arrays=lambda a: a.update(lengths=a["lengths"] + 1e-8))
    edited_npz(rm, root / "rm-length-1e-11.npz", arrays=lambda a: a.update(lengths=a["lengths"] + 1e-11))
    edited_npz(rm, root / "rm-node-alone.npz",
               arrays=lambda a: a.update(nodes=np.vstack([a["nodes"], np.zeros((1, a["nodes"].shape[1]))])))
    edited_npz(rm, root / "rm-evil.npz", lambda m: m.update(constraint=EVIL) or m["task"].update(constraint=EVIL))
    edited_npz(root / "path.npz", root / "p-evil.npz", lambda m: m.update(sampler="evilmod:C", planner="evilmod:C"))
    model_copy(root, "m-evil", set_key("model", value="evilmod:C"))
    shutil.copytree(root / "bench", root / "b-ghost")
    record = json.loads((root / "bench" / "runs.jsonl").read_text().splitlines()[0])
    with open(root / "b-ghost" / "runs.jsonl", "a") as runs:
        runs.write(json.dumps({**record, "method": "ghost"}) + "\n")
    (root / "cfg-rnage.toml").write_text("rnage = 0.8\n")
    (root / "cfg-range.toml").write_text("range = 0.8\n")
    (root / "cfg-latent.toml").write_text("latent = 2\nhidden = [16]\n")


def make(root: Path) -> None:
    tasks(root)
    user_modules(root)
    scenes(root)
    edited(root)
