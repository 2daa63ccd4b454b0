"""The hostile table: odd numbers, wrong types, odd files (empty, folders, pipes, links, deep nesting), user code
that fails, conflicting options. Every case ends as documented: a refusal is exit code 2 and one line naming the
problem (no traceback, no input changed, nothing half-written); an accepted case does what it says; a case that
could hang runs in a subprocess under a timeout; nothing a data file holds is ever executed."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.data import collect
from manifoldgen.dataset import Dataset
from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import load_npz, save_npz
from manifoldgen.models import CVAE, load_model
from manifoldgen.planning.result import path_length
from manifoldgen.tasks import BUILTIN_DIR, get_task, load_task_file
from refusals import reseal

runner = CliRunner()
TINY = {"hidden": [8], "batch": 8, "epochs": 1, "patience": 5}
POSE = (BUILTIN_DIR / "pose-panda.toml").read_text().replace('"scenes/', f'"{BUILTIN_DIR}/scenes/')
USER = Path(__file__).resolve().parent.parent / "examples" / "user_task"
MARK = "pwned"  # a file that code run from a data file would create in the inputs folder


class Payload:
    """Unpickling it creates the mark file: a data file that executes code when read."""

    def __init__(self, target: str):
        self.target = target

    def __reduce__(self):
        return (open, (self.target, "w"))


def _remeta(source: Path, target: Path, edit=None, **arrays) -> None:
    meta, old = load_npz(source, ())
    if edit:
        edit(meta)
    save_npz(target, meta, **{**old, **arrays})


USER_MODULES = {  # module name -> source: a user constraint that fails in one place
    "imp_raises": "1 / 0\n",
    "imp_syntax": "def broken(:\n",
    "init_raises": "from tool_down import ToolDownAtX\nclass C(ToolDownAtX):\n"
                   "    def __init__(self, *a, **k):\n        raise ValueError('no frame for you')\n",
    "res_raises": "from tool_down import ToolDownAtX\nclass C(ToolDownAtX):\n"
                  "    def residual(self, q, y):\n        return 1 / 0\n",
    "res_nan": "from tool_down import ToolDownAtX\nclass C(ToolDownAtX):\n"
               "    def residual(self, q, y):\n        return super().residual(q, y) * float('nan')\n",
    "res_shape": "from tool_down import ToolDownAtX\nclass C(ToolDownAtX):\n"
                 "    def residual(self, q, y):\n        return super().residual(q, y)[:, :1]\n",
    "jac_raises": "from tool_down import ToolDownAtX\nclass C(ToolDownAtX):\n"
                  "    def jacobian(self, q, y):\n        raise KeyError('jac')\n",
    "ineq_nan": "from tool_down import ToolDownAtX\nclass C(ToolDownAtX):\n"
                "    def inequality(self, q, y):\n        return q[:, :1] * float('nan')\n",
    "ineq_int": "from tool_down import ToolDownAtX\nclass C(ToolDownAtX):\n"
                "    def inequality(self, q, y):\n        return 5\n",
    "not_class": "C = 5\n",
    "exits": "import sys\nsys.exit(3)\n",
}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, panda_task, planned_path):
    """Small input files made once: dataset, model, path, and hostile variants of each."""
    root = tmp_path_factory.mktemp("hostile")
    data = collect(panda_task, 5, seed=0, conditions=[[0.3], [0.5]], progress=False)
    data.save(root / "data.npz")
    CVAE(**TINY).fit(data, seed=0, progress=False, out=root / "model")
    shutil.copy(planned_path("wall"), root / "path.npz")
    os.mkfifo(root / "pipe")
    (root / "empty").write_text("")
    (root / "dir.npz").mkdir()
    (root / "dir.json").mkdir()
    (root / "dir.toml").mkdir()
    os.symlink(root / "data.npz", root / "link.npz")
    os.symlink(root / "nowhere.npz", root / "dangling.npz")
    os.symlink(root / "pipe", root / "pipe.toml")
    os.symlink(root / "pipe", root / "pipe.json")
    os.symlink(root / "pipe", root / "pipe.npz")
    # datasets
    q, y = data.q, data.y
    _remeta(root / "data.npz", root / "data-offmanifold.npz", q=q + 0.5)
    _remeta(root / "data-offmanifold.npz", root / "data-outside-limits.npz", q=q + 10.0)
    _remeta(root / "data.npz", root / "data-meta-nested.npz")
    meta, _ = load_npz(root / "data.npz", ())
    np.savez(root / "data-deep-meta.npz", meta=np.array("[" * 100_000 + "]" * 100_000), q=q, y=y)
    np.savez(root / "data-pickle.npz", meta=np.array(json.dumps(meta)), q=np.array([Payload(str(root / MARK))] * 3,
                                                                                    dtype=object), y=y)
    np.savez(root / "data-int.npz", meta=np.array(json.dumps(meta)), q=np.round(q).astype(np.int64), y=y)
    np.savez(root / "data-bool.npz", meta=np.array(json.dumps(meta)), q=q > 0, y=y)
    np.savez(root / "data-complex.npz", meta=np.array(json.dumps(meta)), q=q + 1j, y=y)
    np.savez(root / "data-3d.npz", meta=np.array(json.dumps(meta)), q=q[None], y=y)
    np.savez(root / "data-empty.npz", meta=np.array(json.dumps(meta)), q=q[:0], y=y[:0])
    np.savez(root / "data-y-nan.npz", meta=np.array(json.dumps(meta)), q=q, y=np.full_like(y, np.nan))
    np.savez(root / "data-y-wide.npz", meta=np.array(json.dumps(meta)), q=q, y=np.hstack([y, y]))
    np.savez(root / "data-meta-list.npz", meta=np.array("[1, 2]"), q=q, y=y)
    np.savez(root / "data-meta-nan.npz", meta=np.array(json.dumps({**meta, "format_version": float("nan")})), q=q, y=y)
    np.savez(root / "data-meta-bytes.npz", meta=np.frombuffer(b"\xff\xfe\x00", np.uint8), q=q, y=y)
    np.savez(root / "data-joints-str.npz", meta=np.array(json.dumps({**meta, "joints": "panda_joint1"})), q=q, y=y)
    with open(root / "data-huge-header.npz", "wb") as f:  # an .npz whose q claims 10^12 rows
        import zipfile
        with zipfile.ZipFile(f, "w") as z:
            header = ("{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000000, 7), }").ljust(117) + "\n"
            z.writestr("q.npy", b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode() + b"\0" * 64)
            z.writestr("y.npy", _npy(y))
            z.writestr("meta.npy", _npy(np.array(json.dumps(meta))))
    # models, re-signed with their checksum recomputed
    for name, edit in (("model-std-zero", lambda d: d["normalisation"].__setitem__(
                            "q_std", [0.0] * len(d["normalisation"]["q_std"]))),
                       ("model-std-nan", lambda d: d["normalisation"]["q_std"].__setitem__(0, float("nan"))),
                       ("model-range-flipped", lambda d: d["normalisation"].update(
                           y_low=d["normalisation"]["y_high"], y_high=d["normalisation"]["y_low"])),
                       ("model-hidden-huge", lambda d: d["config"].update(hidden=[1_000_000_000])),
                       ("model-hidden-text", lambda d: d["config"].update(hidden="eight")),
                       ("model-hidden-other", lambda d: d["config"].update(hidden=[16])),
                       ("model-kind-code", lambda d: d.update(model="os:system")),
                       ("model-kind-unknown", lambda d: d.update(model="cgan2")),
                       ("model-latent-bool", lambda d: d["config"].update(latent=True)),
                       ("model-dims-huge", lambda d: d["dims"].update(d=10 ** 12)),
                       ("model-meta-task-code", lambda d: d["meta"]["task"]["constraint"].update(type="this:X")),
                       ("model-joints-short", lambda d: d["meta"].update(joints=d["meta"]["joints"][:3])),
                       ("model-decoder-noise", lambda d: d["decoder"].update(noise=50)),
                       ("model-decoder-steps", lambda d: d["decoder"].update(steps=10 ** 6))):
        shutil.copytree(root / "model", root / name)
        reseal(root / name, edit)
    shutil.copytree(root / "model", root / "model-deep")
    (root / "model-deep" / "model.json").write_text("[" * 100_000 + "]" * 100_000)
    shutil.copytree(root / "model", root / "model-dup-keys")
    text = (root / "model" / "model.json").read_text()
    (root / "model-dup-keys" / "model.json").write_text('{"model": "cgan", ' + text.lstrip()[1:])
    shutil.copytree(root / "model", root / "model-json-dir")
    (root / "model-json-dir" / "model.json").unlink()
    (root / "model-json-dir" / "model.json").mkdir()
    shutil.copytree(root / "model", root / "model-json-pipe")
    (root / "model-json-pipe" / "model.json").unlink()
    os.mkfifo(root / "model-json-pipe" / "model.json")
    shutil.copytree(root / "model", root / "model-weights-empty")
    (root / "model-weights-empty" / "model.safetensors").write_bytes(b"")
    # path files
    meta, arrays = load_npz(root / "path.npz", ("path",))
    path = arrays["path"]
    for name, edited in (("one", path[:1]), ("still", np.repeat(path[:1], 2, axis=0)),
                         ("outside-limits", path + np.r_[0, 0, 0, 0, 0, 0, 5.0]), ("offmanifold", path + 0.3),
                         ("int", np.round(path).astype(np.int64))):  # its meta's start, goal and result: its own
        result = {**meta["result"], "waypoints": len(edited), "length": path_length(np.asarray(edited, float))}
        save_npz(root / f"path-{name}.npz", {**meta, "start": edited[0].tolist(), "goal": edited[-1].tolist(),
                                             "result": result}, path=edited)
    save_npz(root / "path-3d.npz", meta, path=path[None])
    save_npz(root / "path-condition-nan.npz", {**meta, "condition": [float("nan")]}, path=path)
    save_npz(root / "path-condition-str.npz", {**meta, "condition": "0.5"}, path=path)
    save_npz(root / "path-scene-bad.npz", {**meta, "scene": {"obstacles": "many"}}, path=path)
    save_npz(root / "path-scene-nan.npz", {**meta, "scene": {**meta["scene"], "condition": [float("nan")]}},
             path=path) if isinstance(meta.get("scene"), dict) else None
    save_npz(root / "path-tolerance.npz", {**meta, "tolerance": [1e9] * len(meta["tolerance"])}, path=path)
    save_npz(root / "path-robot-other.npz", {**meta, "robot": "pr2"}, path=path)
    save_npz(root / "path-task-file.npz", {**meta, "task": {**meta["task"], "task_file": str(root / "evil" / "x.toml")}},
             path=path)
    (root / "evil").mkdir()
    (root / "evil" / "toppra.py").write_text(f"open({str(root / MARK)!r}, 'w')\n")
    (root / "evil" / "matplotlib.py").write_text(f"open({str(root / MARK)!r}, 'w')\n")
    # scenes
    wall = json.loads((BUILTIN_DIR / "scenes" / "panda-wall.json").read_text())
    scenes = {
        "scene-dup-keys": json.dumps(wall)[:-1] + ', "condition": [0.9]}',
        "scene-deep": '{"obstacles": ' + "[" * 100_000 + "]" * 100_000 + "}",
        "scene-nan-condition": json.dumps({**wall, "condition": [float("nan")]}),
        "scene-inf-size": json.dumps({**wall, "obstacles": [{"type": "box", "size": [float("inf")] * 3,
                                                             "pose": {"position": [2, 0, 0]}}]}),
        "scene-condition-str": json.dumps({**wall, "condition": "0.5"}),
        "scene-condition-bool": json.dumps({**wall, "condition": [True]}),
        "scene-obstacles-dict": json.dumps({**wall, "obstacles": {"type": "box"}}),
        "scene-obstacle-untyped": json.dumps({**wall, "obstacles": [{"size": [1, 1, 1]}]}),
        "scene-obstacle-cube": json.dumps({**wall, "obstacles": [{"type": "cube", "size": [1, 1, 1],
                                                                  "pose": {"position": [2, 0, 0]}}]}),
        "scene-size-zero": json.dumps({**wall, "obstacles": [{"type": "box", "size": [0, 0, 0],
                                                              "pose": {"position": [2, 0, 0]}}]}),
        "scene-quat-zero": json.dumps({**wall, "obstacles": [{"type": "box", "size": [0.1, 0.1, 0.1],
                                                              "pose": {"position": [2, 0, 0],
                                                                       "quaternion": [0, 0, 0, 0]}}]}),
        "scene-quat-nan": json.dumps({**wall, "obstacles": [{"type": "box", "size": [0.1, 0.1, 0.1],
                                                             "pose": {"position": [2, 0, 0],
                                                                      "quaternion": [float("nan"), 0, 0, 1]}}]}),
        "scene-position-short": json.dumps({**wall, "obstacles": [{"type": "box", "size": [0.1, 0.1, 0.1],
                                                                   "pose": {"position": [2, 0]}}]}),
        "scene-radius-str": json.dumps({**wall, "obstacles": [{"type": "sphere", "radius": "0.1",
                                                               "pose": {"position": [2, 0, 0]}}]}),
        "scene-version-2": json.dumps({**wall, "format_version": 2}),
        "scene-version-str": json.dumps({**wall, "format_version": "1"}),
        "scene-start-str": json.dumps({**wall, "start": "home"}),
        "scene-start-limits": json.dumps({**wall, "start": [10.0] * 7}),
        "scene-start-nan": json.dumps({**wall, "start": [float("nan")] * 7}),
        "scene-start-offmanifold": json.dumps({**wall, "start": [0.0] * 7}),
        "scene-target-typo": json.dumps({**wall, "goal": {"positon": [0.4, 0.0, 0.5]}}),
        "scene-target-frame": json.dumps({**wall, "goal": {"position": [0.4, 0.0, 0.5], "frame": "nohand"}}),
        "scene-target-far": json.dumps({**wall, "goal": {"position": [40.0, 0.0, 0.5]}}),
        "scene-target-offmanifold": json.dumps({**wall, "goal": {"position": [0.4, 0.0, 0.9]}}),
        "scene-null": "null",
        "scene-attached-typo": json.dumps({**wall, "attached": {"frme": "panda_hand"}}),
        "scene-mesh-pipe": json.dumps({**wall, "obstacles": [{"type": "mesh", "mesh": str(root / "pipe"),
                                                             "pose": {"position": [2, 0, 0]}}]}),
        "scene-mesh-dir": json.dumps({**wall, "obstacles": [{"type": "mesh", "mesh": str(root),
                                                            "pose": {"position": [2, 0, 0]}}]}),
        "scene-robot-list": json.dumps({**wall, "robot": ["panda"]}),
        "scene-name-list": json.dumps({**wall, "name": ["wall"]}),
        "scene-bom": "\ufeff" + json.dumps(wall),
    }
    for name, text in scenes.items():
        (root / f"{name}.json").write_text(text, encoding="utf-8")
    (root / "scene-binary.json").write_bytes(b"\x00\x01\x02\xff" * 10)
    # task files
    tasks = {
        "task-rotation-scaled": POSE.replace("[[1.0, 0.0, 0.0], [0.0, -1.0", "[[2.0, 0.0, 0.0], [0.0, -1.0"),
        "task-rotation-nan": POSE.replace("[[1.0, 0.0, 0.0], [0.0, -1.0", "[[nan, 0.0, 0.0], [0.0, -1.0"),
        "task-rotation-2x2": POSE.replace("[[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]", "[[1.0, 0.0], [0.0, 1.0]]"),
        "task-values-empty": POSE.replace("values = [[0.2], [0.3], [0.4], [0.5], [0.6], [0.7]]", "values = []"),
        "task-values-nan": POSE.replace("values = [[0.2], [0.3]", "values = [[nan], [0.3]"),
        "task-values-str": POSE.replace("values = [[0.2], [0.3]", 'values = [["high"], [0.3]'),
        "task-values-flat": POSE.replace("values = [[0.2], [0.3], [0.4], [0.5], [0.6], [0.7]]", "values = [0.2, 0.3]")
        .replace("home_condition = [0.45]", "home_condition = [0.25]"),
        "task-values-dup": POSE.replace("values = [[0.2], [0.3]", "values = [[0.3], [0.3]"),
        "task-home-short": POSE.replace("home = [0.0, -0.785398, 0.0, -2.35619, 0.0, 1.5707, 0.785398]", "home = [0.0, 1.0]"),
        "task-home-nan": POSE.replace("home = [0.0, -0.785398", "home = [nan, -0.785398"),
        "task-home-limits": POSE.replace("home = [0.0, -0.785398", "home = [100.0, -0.785398"),
        "task-home-condition-nan": POSE.replace("home_condition = [0.45]", "home_condition = [nan]"),
        "task-home-condition-long": POSE.replace("home_condition = [0.45]", "home_condition = [0.45, 0.1]"),
        "task-locked-str": POSE.replace("[[constraints]]", "[locked]\npanda_finger_joint1 = \"open\"\n\n[[constraints]]"),
        "task-locked-unknown": POSE.replace("[[constraints]]", "[locked]\nnosuchjoint = 0.01\n\n[[constraints]]"),
        "task-locked-limits": POSE.replace("[[constraints]]", "[locked]\npanda_finger_joint1 = 100.0\n\n[[constraints]]"),
        "task-locked-nan": POSE.replace("[[constraints]]", "[locked]\npanda_finger_joint1 = nan\n\n[[constraints]]"),
        "task-scene-missing": POSE.replace(f'wall = "{BUILTIN_DIR}/scenes/panda-wall.json"', 'wall = "missing.json"'),
        "task-scene-number": POSE.replace(f'wall = "{BUILTIN_DIR}/scenes/panda-wall.json"', "wall = 3"),
        "task-scene-dir": POSE.replace(f'wall = "{BUILTIN_DIR}/scenes/panda-wall.json"', 'wall = "dir.json"'),
        "task-scene-pipe": POSE.replace(f'wall = "{BUILTIN_DIR}/scenes/panda-wall.json"', 'wall = "pipe.json"'),
        "task-constraint-untyped": POSE.replace('type = "pose"\n', ""),
        "task-no-constraints": POSE[:POSE.index("[[constraints]]")],
        "task-description-number": POSE.replace('description = "gripper', 'description = 5\nnotes = "gripper'),
        "task-planner-nan": POSE + "\n[planner]\nrange = nan\n",
        "task-planner-inf": POSE + "\n[planner]\nrange = inf\n",
        "task-planner-huge": POSE + "\n[planner]\nreach = 1e308\n",
        "task-robot-dir": POSE.replace('robot = "panda"', f'robot = "{root}"'),
        "task-robot-missing": POSE.replace('robot = "panda"', 'robot = "../../no/such.urdf"'),
        "task-robot-pipe": POSE.replace('robot = "panda"', f'robot = "{root / "pipe"}"'),
        "task-srdf-pipe": POSE.replace('robot = "panda"', f'robot = "panda"\nsrdf = "{root / "pipe"}"'),
        "task-axes-unknown": POSE.replace('position_axes = ["z"]', 'position_axes = ["w"]'),
        "task-axes-empty": POSE.replace('position_axes = ["z"]', "position_axes = []"),
        "task-deep": "name = " + "[" * 50_000 + "]" * 50_000 + "\n",
        "task-base-bounds-fixed": POSE.replace('robot = "panda"', 'robot = "panda"\nbase_bounds = [[0, 0, 0], [1, 1, 1]]'),
        "task-floating-panda": POSE.replace('robot = "panda"', 'robot = "panda"\nfloating_base = true'),
        "task-tolerance-huge": POSE.replace('position_axes = ["z"]', 'position_axes = ["z"]\nposition_tolerance = 1e308'),
        "task-lock-group-joint": POSE.replace("[[constraints]]", "[locked]\npanda_joint1 = 0.3\n\n[[constraints]]", 1),
    }
    for name, text in tasks.items():
        (root / f"{name}.toml").write_text(text)
    (root / "task-binary.toml").write_bytes(b"\x00\xff\xfe" * 10)
    (root / "task.json").write_text(POSE)
    # a user's constraint that fails in one place, each beside its own task file
    for module, source in USER_MODULES.items():
        folder = root / f"user-{module}"
        folder.mkdir()
        shutil.copy(USER / "tool_down.py", folder / "tool_down.py")
        (folder / f"{module}.py").write_text(source)
        task = (USER / "tool-down-xarm7.toml").read_text().replace("tool_down:ToolDownAtX", f"{module}:C")
        task = task.replace('open = "open.json"', f'open = "{USER / "open.json"}"')
        (folder / "task.toml").write_text(task)
    # configs
    (root / "config-deep.toml").write_text("hidden = " + "[" * 50_000 + "]" * 50_000 + "\n")
    (root / "config-nested.toml").write_text("[cvae]\nhidden = [8]\n")
    (root / "config-nan.toml").write_text("lr = nan\n")
    (root / "out-ro").mkdir()
    return root


def _npy(array: np.ndarray) -> bytes:
    import io
    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def _digest(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file() and not p.is_symlink()}


@dataclass
class Case:
    """A command line (``{I}``: the inputs folder, ``{O}``: a fresh output folder) or an API call ``call(I, O)``;
    ``code`` the exit code (2: a one-line refusal, whose line holds every word of ``needle``; 0 or 1: the output
    holds them); ``proc``: a case that could hang (it is watched: see :func:`_watched`)."""

    id: str
    needle: tuple[str, ...]
    args: list[str] | None = None
    call: object = None
    code: int = 2
    proc: bool = False


def cli(id, args, *needle, code=2, proc=False):
    return Case(id, needle, args=args.split(), code=code, proc=proc)


def api(id, call, *needle):
    return Case(id, needle, call=call)


def _user(module):
    return f"{{I}}/user-{module}/task.toml"


CASES = [
    # odd numbers in numeric options
    cli("collect-near-home-nan", "collect pose --near-home nan --per-condition 5 -o {O}/x.npz", "near", "nan"),
    cli("collect-near-home-negative", "collect pose --near-home -1 --per-condition 5 -o {O}/x.npz", "near", "-1"),
    cli("collect-near-home-inf", "collect pose --near-home inf --per-condition 5 -o {O}/x.npz", "near", "inf"),
    cli("collect-condition-inf", "collect pose --condition inf --per-condition 5 -o {O}/x.npz", "inf"),
    cli("collect-seed-overflow", "collect pose --condition 0.3 --condition 0.4 --condition 0.5 "
        "--per-condition 5 --seed 4294967296 -o {O}/x.npz", "--seed", "4294967296"),
    cli("collect-per-condition-huge-int", "collect pose --per-condition 99999999999999999999 -o {O}/x.npz",
        "99999999999999999999"),
    cli("collect-condition-1e308", "collect pose --condition 1e308 --per-condition 5 -o {O}/x.npz", "1e+308"),
    cli("train-threads-zero", "train {I}/data.npz --threads 0 -o {O}/m", "--threads", "0"),
    cli("train-threads-negative", "train {I}/data.npz --threads -4 -o {O}/m", "--threads", "-4"),
    cli("train-epochs-negative", "train {I}/data.npz --epochs -1 -o {O}/m", "-1"),
    cli("train-epochs-huge", "train {I}/data.npz --model cvae --epochs 100000000000 -o {O}/m", "--epochs"),
    cli("train-seed-huge", "train {I}/data.npz --seed 18446744073709551616 -o {O}/m", "--seed"),
    cli("train-lr-nan", "train {I}/data.npz --model cvae --set lr=NaN -o {O}/m", "lr", "nan"),
    cli("train-lr-inf", "train {I}/data.npz --model cvae --set lr=Infinity -o {O}/m", "lr", "inf"),
    cli("train-hidden-float", "train {I}/data.npz --model cvae --set hidden=[8.5] -o {O}/m", "hidden"),
    cli("train-hidden-bool", "train {I}/data.npz --model cvae --set hidden=[true,8] -o {O}/m", "hidden"),
    cli("train-hidden-string", "train {I}/data.npz --model cvae --set hidden=\"8\" -o {O}/m", "hidden"),
    cli("train-hidden-deep", "train {I}/data.npz --model cvae --set hidden=[[8]] -o {O}/m", "hidden"),
    cli("train-latent-huge", "train {I}/data.npz --model cvae --set latent=100000000000 -o {O}/m", "latent"),
    cli("train-latent-negative", "train {I}/data.npz --model cvae --set latent=-2 -o {O}/m", "latent"),
    cli("train-batch-above-rows", "train {I}/data.npz --model cvae --set batch=100000000000000 --set hidden=[8] "
        "--epochs 1 -o {O}/m", "trained", code=0),
    cli("train-patience-negative", "train {I}/data.npz --model cvae --set patience=-1 -o {O}/m", "patience"),
    cli("train-set-empty-key", "train {I}/data.npz --model cvae --set =5 -o {O}/m", "=5"),
    cli("train-set-bad-json", "train {I}/data.npz --model cvae --set hidden=[8,, -o {O}/m", "hidden"),
    cli("sample-n-huge-int", "sample {I}/model --condition 0.4 -n 99999999999999999999 -o {O}/s.npz", "-n"),
    cli("sample-condition-inf", "sample {I}/model --condition inf -o {O}/s.npz", "inf"),
    cli("sample-condition-two", "sample {I}/model --condition 0.4 --condition 0.5 -o {O}/s.npz", "condition"),
    cli("sample-seed-huge", "sample {I}/model --condition 0.4 --seed 4294967296 -o {O}/s.npz", "--seed"),
    cli("sample-minus-zero", "sample {I}/model --condition -0.0 --strict -n 5 -o {O}/s.npz", "-0"),
    cli("plan-time-inf", "plan pose --scene wall --time inf -o {O}/p.npz", "--time", "inf"),
    cli("plan-time-tiny", "plan pose --scene wall --time 1e-9 -o {O}/p.npz", "--time"),
    cli("plan-time-minus-zero", "plan pose --scene wall --time -0.0 -o {O}/p.npz", "--time"),
    cli("plan-range-nan", "plan pose --scene wall --set range=NaN -o {O}/p.npz", "range", "nan"),
    cli("plan-range-inf", "plan pose --scene wall --set range=Infinity -o {O}/p.npz", "range"),
    cli("plan-range-string", "plan pose --scene wall --set range=\"far\" -o {O}/p.npz", "range"),
    cli("plan-batch-huge", "plan pose --scene wall --sampler project,batch=100000000000 -o {O}/p.npz", "batch"),
    cli("plan-batch-float", "plan pose --scene wall --sampler project,batch=2.5 -o {O}/p.npz", "batch"),
    cli("plan-sampler-empty-path", "plan pose --scene wall --sampler cvae: -o {O}/p.npz", "cvae"),
    cli("plan-sampler-pg-empty", "plan pose --scene wall --sampler pg: -o {O}/p.npz", "pg"),
    cli("bench-sampling-threads-huge", "bench sampling {I}/model --threads 100000 -o {O}/b", "--threads", "100000"),
    cli("bench-sampling-threads-zero", "bench sampling {I}/model --threads 0 -o {O}/b", "--threads", "0"),
    cli("bench-sampling-threads-negative", "bench sampling {I}/model --threads -3 -o {O}/b", "--threads", "-3"),
    cli("bench-sampling-repeats-huge", "bench sampling {I}/model --repeats 1000000000 -o {O}/b", "--repeats"),
    cli("bench-sampling-reference-huge", "bench sampling {I}/model --reference 1000000000000 -o {O}/b", "--reference"),
    cli("bench-sampling-refine-huge", "bench sampling {I}/model --refine 100000000 -o {O}/b", "--refine"),
    cli("bench-sampling-seen-nan", "bench sampling {I}/model --seen nan -o {O}/b", "nan"),
    cli("bench-sampling-seen-inf", "bench sampling {I}/model --unseen inf -o {O}/b", "inf"),
    cli("bench-sampling-seen-two", "bench sampling {I}/model --seen 0.3,0.4 -o {O}/b", "0.3"),
    cli("bench-sampling-seen-empty", "bench sampling {I}/model --seen , -o {O}/b", "conditions"),
    cli("bench-plan-workers-huge", "bench plan pose --scene wall -m rrtconnect@project --workers 100000 -o {O}/b",
        "--workers"),
    cli("bench-plan-workers-negative", "bench plan pose --scene wall -m rrtconnect@project --workers -2 -o {O}/b",
        "-2"),
    cli("bench-plan-time-nan", "bench plan pose --scene wall -m rrtconnect@project --time nan -o {O}/b", "--time"),
    cli("bench-plan-time-inf", "bench plan pose --scene wall -m rrtconnect@project --time inf -o {O}/b", "--time"),
    cli("bench-plan-pg-rows-huge", "bench plan pose --scene wall -m rrtconnect@pg --pg-rows 1000000000000 -o {O}/b",
        "--pg-rows"),
    cli("bench-plan-runs-negative", "bench plan pose --scene wall -m rrtconnect@project --runs -1 -o {O}/b", "--runs"),
    cli("bench-plan-range-nan", "bench plan pose --scene wall -m rrtconnect@project --set range=NaN -o {O}/b", "range"),
    cli("bench-plan-seed-overflow", "bench plan pose --scene wall -m rrtconnect@project --runs 10 --seed 4294967295 "
        "-o {O}/b", "seed"),
    cli("physics-friction-nan", "physics {I}/path.npz --friction nan", "friction", "nan"),
    cli("physics-friction-negative", "physics {I}/path.npz --friction -1", "friction", "-1"),
    cli("physics-tilt-negative", "physics {I}/path.npz --tilt -5", "tilt", "-5"),
    cli("physics-tilt-huge", "physics {I}/path.npz --tilt 400", "tilt", "400"),
    cli("physics-settle-nan", "physics {I}/path.npz --settle nan", "--settle", "nan"),
    cli("physics-fixed-base", "physics {I}/path.npz", "fixed base"),
    cli("physics-output-over-input", "physics {I}/path.npz -o {I}/path.npz", "path.npz"),
    cli("trajectory-dt-tiny", "trajectory {I}/path.npz --dt 1e-12 -o {O}/t.json", "--dt"),
    cli("trajectory-dt-huge", "trajectory {I}/path.npz --dt 1e308 -o {O}/t.json", "--dt"),
    cli("trajectory-dt-nan", "trajectory {I}/path.npz --dt nan -o {O}/t.json", "--dt", "nan"),
    cli("trajectory-vel-tiny", "trajectory {I}/path.npz --vel-scale 1e-300 -o {O}/t.json", "--vel-scale"),
    cli("trajectory-acc-nan", "trajectory {I}/path.npz --acc-scale nan -o {O}/t.json", "--acc-scale"),
    cli("trajectory-vel-above-one", "trajectory {I}/path.npz --vel-scale 1.5 -o {O}/t.json", "--vel-scale"),
    cli("trajectory-suffix-upper", "trajectory {I}/path.npz -o {O}/T.JSON", "trajectory", code=0),
    cli("view-port-negative", "view {I}/path.npz --port -1", "--port", "-1"),
    cli("view-port-huge", "view {I}/path.npz --port 70000", "--port", "70000"),
    cli("view-host-bad", "view {I}/path.npz --host not..a..host --port 8999", "cannot serve on host"),
    cli("view-export-and-snapshots", "view {I}/path.npz --export {O}/v.html --snapshots {O}/v.png", "--export",
        "--snapshots"),
    # files that are not what they should be
    cli("train-dataset-empty-file", "train {I}/empty -o {O}/m", "empty"),
    cli("train-dataset-symlink-ok", "train {I}/link.npz --model cvae --set hidden=[8] --epochs 1 -o {O}/m",
        "trained", code=0),
    cli("train-dataset-dangling", "train {I}/dangling.npz -o {O}/m", "dangling.npz"),
    cli("train-dataset-pipe-link", "train {I}/pipe.npz -o {O}/m", "not a regular file", proc=True),
    cli("train-dataset-deep-meta", "train {I}/data-deep-meta.npz -o {O}/m", "data-deep-meta.npz"),
    cli("train-dataset-pickle", "train {I}/data-pickle.npz -o {O}/m", "data-pickle.npz", "object array",
        "never loaded"),
    cli("train-dataset-bool", "train {I}/data-bool.npz -o {O}/m", "data-bool.npz"),
    cli("train-dataset-complex", "train {I}/data-complex.npz -o {O}/m", "data-complex.npz"),
    cli("train-dataset-3d", "train {I}/data-3d.npz -o {O}/m", "data-3d.npz"),
    cli("train-dataset-no-rows", "train {I}/data-empty.npz -o {O}/m", "0 rows"),
    cli("train-dataset-y-nan", "train {I}/data-y-nan.npz -o {O}/m", "NaN"),
    cli("train-dataset-y-wide", "train {I}/data-y-wide.npz -o {O}/m", "must hold a number per condition column (2)"),
    cli("train-dataset-meta-list", "train {I}/data-meta-list.npz -o {O}/m", "meta"),
    cli("train-dataset-meta-nan", "train {I}/data-meta-nan.npz -o {O}/m", "format"),
    cli("train-dataset-meta-bytes", "train {I}/data-meta-bytes.npz -o {O}/m", "meta"),
    cli("train-dataset-joints-str", "train {I}/data-joints-str.npz -o {O}/m", "joints"),
    cli("train-dataset-huge-header", "train {I}/data-huge-header.npz -o {O}/m", "data-huge-header.npz"),
    cli("train-dataset-off-manifold", "train {I}/data-offmanifold.npz --model cvae -o {O}/m", "does not satisfy",
        "tolerance"),
    cli("train-dataset-outside-limits", "train {I}/data-outside-limits.npz --model cvae -o {O}/m", "limits"),
    cli("train-dataset-int", "train {I}/data-int.npz --model cvae -o {O}/m", "does not satisfy"),
    cli("train-output-is-symlink-to-input", "train {I}/data.npz -o {I}/link.npz", "link.npz"),
    cli("train-output-dotdot-input", "train {I}/data.npz -o {I}/model/../data.npz", "data.npz"),
    cli("sample-output-dotdot-model-file", "sample {I}/model --condition 0.4 -o {I}/model/../model/model.json",
        "model.json"),
    cli("train-config-pipe", "train {I}/data.npz --model cvae --config {I}/pipe.toml -o {O}/m", "pipe.toml", proc=True),
    cli("train-config-deep", "train {I}/data.npz --model cvae --config {I}/config-deep.toml -o {O}/m", "config-deep"),
    cli("train-config-nested", "train {I}/data.npz --model cvae --config {I}/config-nested.toml -o {O}/m", "cvae"),
    cli("train-config-nan", "train {I}/data.npz --model cvae --config {I}/config-nan.toml -o {O}/m", "lr", "nan"),
    cli("train-config-empty-ok", "train {I}/data.npz --model cvae --config {I}/empty --set hidden=[8] --epochs 1 "
        "-o {O}/m", "trained", code=0),
    cli("train-auto-with-epochs-model-code", "train {I}/data.npz --model os:system -o {O}/m", "os:system"),
    cli("sample-model-std-zero", "sample {I}/model-std-zero --condition 0.4 -o {O}/s.npz", "standard deviations"),
    cli("sample-model-std-nan", "sample {I}/model-std-nan --condition 0.4 -o {O}/s.npz", "q_std"),
    cli("sample-model-range-flipped", "sample {I}/model-range-flipped --condition 0.4 -o {O}/s.npz", "lower bound"),
    cli("sample-model-hidden-huge", "sample {I}/model-hidden-huge --condition 0.4 -o {O}/s.npz", "hidden"),
    cli("sample-model-hidden-text", "sample {I}/model-hidden-text --condition 0.4 -o {O}/s.npz", "hidden"),
    cli("sample-model-hidden-other", "sample {I}/model-hidden-other --condition 0.4 -o {O}/s.npz",
        "gives config hidden = [16], but its 'decoder' weights have [8]"),
    cli("sample-model-kind-code", "sample {I}/model-kind-code --condition 0.4 -o {O}/s.npz", "os:system"),
    cli("sample-model-kind-unknown", "sample {I}/model-kind-unknown --condition 0.4 -o {O}/s.npz", "cgan2"),
    cli("sample-model-latent-bool", "sample {I}/model-latent-bool --condition 0.4 -o {O}/s.npz", "latent"),
    cli("sample-model-dims-huge", "sample {I}/model-dims-huge --condition 0.4 -o {O}/s.npz", "model.json"),
    cli("sample-model-meta-task-code", "sample {I}/model-meta-task-code --condition 0.4 -o {O}/s.npz", "this:X"),
    cli("sample-model-joints-short", "sample {I}/model-joints-short --condition 0.4 -o {O}/s.npz", "joints"),
    cli("sample-model-deep", "sample {I}/model-deep --condition 0.4 -o {O}/s.npz", "model.json"),
    cli("sample-model-dup-keys", "sample {I}/model-dup-keys --condition 0.4 -o {O}/s.npz", "'model' appears twice"),
    cli("sample-model-json-dir", "sample {I}/model-json-dir --condition 0.4 -o {O}/s.npz", "model.json"),
    cli("sample-model-json-pipe", "sample {I}/model-json-pipe --condition 0.4 -o {O}/s.npz", "model.json", proc=True),
    cli("sample-model-weights-empty", "sample {I}/model-weights-empty --condition 0.4 -o {O}/s.npz",
        "model.safetensors"),
    cli("sample-output-symlink-to-input", "sample {I}/model --condition 0.4 -o {I}/pipe.npz", "not a regular file"),
    cli("sample-task-pipe", "sample {I}/model --condition 0.4 --task {I}/pipe.toml -o {O}/s.npz", "pipe.toml",
        proc=True),
    cli("plan-scene-pipe", "plan pose --scene {I}/pipe.json -o {O}/p.npz", "pipe.json", proc=True),
    cli("plan-scene-dir", "plan pose --scene {I}/dir.json -o {O}/p.npz", "directory"),
    cli("plan-scene-empty", "plan pose --scene {I}/empty -o {O}/p.npz", "empty"),
    cli("plan-scene-dup-keys", "plan pose --scene {I}/scene-dup-keys.json -o {O}/p.npz", "condition"),
    cli("plan-scene-deep", "plan pose --scene {I}/scene-deep.json -o {O}/p.npz", "scene-deep.json"),
    cli("plan-scene-nan-condition", "plan pose --scene {I}/scene-nan-condition.json -o {O}/p.npz", "condition"),
    cli("plan-scene-inf-size", "plan pose --scene {I}/scene-inf-size.json -o {O}/p.npz", "size"),
    cli("plan-scene-condition-str", "plan pose --scene {I}/scene-condition-str.json -o {O}/p.npz", "condition"),
    cli("plan-scene-condition-bool", "plan pose --scene {I}/scene-condition-bool.json -o {O}/p.npz", "condition"),
    cli("plan-scene-obstacles-dict", "plan pose --scene {I}/scene-obstacles-dict.json -o {O}/p.npz", "obstacles"),
    cli("plan-scene-obstacle-untyped", "plan pose --scene {I}/scene-obstacle-untyped.json -o {O}/p.npz", "type"),
    cli("plan-scene-obstacle-cube", "plan pose --scene {I}/scene-obstacle-cube.json -o {O}/p.npz", "cube", "box"),
    cli("plan-scene-size-zero", "plan pose --scene {I}/scene-size-zero.json -o {O}/p.npz", "size"),
    cli("plan-scene-quat-zero", "plan pose --scene {I}/scene-quat-zero.json -o {O}/p.npz", "quaternion"),
    cli("plan-scene-quat-nan", "plan pose --scene {I}/scene-quat-nan.json -o {O}/p.npz", "quaternion"),
    cli("plan-scene-position-short", "plan pose --scene {I}/scene-position-short.json -o {O}/p.npz", "position"),
    cli("plan-scene-radius-str", "plan pose --scene {I}/scene-radius-str.json -o {O}/p.npz", "radius"),
    cli("plan-scene-version-2", "plan pose --scene {I}/scene-version-2.json -o {O}/p.npz", "format_version"),
    cli("plan-scene-version-str", "plan pose --scene {I}/scene-version-str.json -o {O}/p.npz", "format_version"),
    cli("plan-scene-start-str", "plan pose --scene {I}/scene-start-str.json -o {O}/p.npz", "start"),
    cli("plan-scene-start-limits", "plan pose --scene {I}/scene-start-limits.json -o {O}/p.npz", "start", "limit"),
    cli("plan-scene-start-nan", "plan pose --scene {I}/scene-start-nan.json -o {O}/p.npz", "start"),
    cli("plan-scene-start-offmanifold", "plan pose --scene {I}/scene-start-offmanifold.json -o {O}/p.npz", "start"),
    cli("plan-scene-target-typo", "plan pose --scene {I}/scene-target-typo.json -o {O}/p.npz", "positon"),
    cli("plan-scene-target-frame", "plan pose --scene {I}/scene-target-frame.json -o {O}/p.npz", "nohand"),
    cli("plan-scene-target-far", "plan pose --scene {I}/scene-target-far.json -o {O}/p.npz", "goal"),
    cli("plan-scene-target-offmanifold", "plan pose --scene {I}/scene-target-offmanifold.json -o {O}/p.npz", "goal"),
    cli("plan-scene-null", "plan pose --scene {I}/scene-null.json -o {O}/p.npz", "JSON object"),
    cli("plan-scene-attached-typo", "plan pose --scene {I}/scene-attached-typo.json -o {O}/p.npz", "frme"),
    cli("plan-scene-mesh-pipe", "plan pose --scene {I}/scene-mesh-pipe.json -o {O}/p.npz", "pipe", proc=True),
    cli("plan-scene-mesh-dir", "plan pose --scene {I}/scene-mesh-dir.json -o {O}/p.npz", "mesh"),
    cli("plan-scene-robot-list", "plan pose --scene {I}/scene-robot-list.json -o {O}/p.npz", "robot"),
    cli("plan-scene-name-list", "plan pose --scene {I}/scene-name-list.json -o {O}/p.npz", "name"),
    cli("plan-scene-binary", "plan pose --scene {I}/scene-binary.json -o {O}/p.npz", "scene-binary.json"),
    cli("plan-output-unicode", "plan pose --scene wall --time 20 -o {O}/pfad-ünï-路径.npz", "solved", code=0),
    cli("plan-output-long-name", "plan pose --scene wall -o {O}/" + "x" * 300 + ".npz", "too long"),
    cli("plan-output-symlink-to-scene", "plan pose --scene {I}/scene-null.json -o {I}/pipe.json", "pipe.json"),
    cli("plan-snapshots-dir", "plan pose --scene wall --snapshots {O} -o {O}/p.npz", "--snapshots"),
    cli("plan-config-empty", "plan pose --scene wall --config {I}/empty --time 20 -o {O}/p.npz", "solved", code=0),
    cli("plan-config-deep", "plan pose --scene wall --config {I}/config-deep.toml -o {O}/p.npz", "config-deep"),
    # task files
    cli("tasks-rotation-scaled", "tasks {I}/task-rotation-scaled.toml", "rotation"),
    cli("tasks-rotation-nan", "tasks {I}/task-rotation-nan.toml", "rotation"),
    cli("tasks-rotation-2x2", "tasks {I}/task-rotation-2x2.toml", "rotation"),
    cli("tasks-values-empty", "tasks {I}/task-values-empty.toml", "values", "at least one value"),
    cli("tasks-values-nan", "tasks {I}/task-values-nan.toml", "values"),
    cli("tasks-values-str", "tasks {I}/task-values-str.toml", "values"),
    cli("tasks-values-flat", "tasks {I}/task-values-flat.toml", "training values 0.2; 0.3", code=0),
    cli("tasks-values-dup", "tasks {I}/task-values-dup.toml", "values", "0.3"),
    cli("tasks-home-short", "tasks {I}/task-home-short.toml", "home"),
    cli("tasks-home-nan", "tasks {I}/task-home-nan.toml", "home must be finite numbers"),
    cli("tasks-home-limits", "tasks {I}/task-home-limits.toml", "home panda_joint1 = 100 is outside its limits"),
    cli("tasks-home-condition-nan", "tasks {I}/task-home-condition-nan.toml", "line 9", "nan"),
    cli("tasks-home-condition-long", "tasks {I}/task-home-condition-long.toml", "line 8", "got 2"),
    cli("tasks-locked-str", "tasks {I}/task-locked-str.toml", "locked", "open"),
    cli("tasks-locked-unknown", "tasks {I}/task-locked-unknown.toml", "nosuchjoint"),
    cli("tasks-locked-limits", "tasks {I}/task-locked-limits.toml", "panda_finger_joint1", "limit"),
    cli("tasks-locked-nan", "tasks {I}/task-locked-nan.toml", "panda_finger_joint1"),
    cli("plan-task-scene-missing", "plan {I}/task-scene-missing.toml --scene wall -o {O}/p.npz", "missing.json"),
    cli("tasks-scene-number", "tasks {I}/task-scene-number.toml", "scene"),
    cli("plan-task-scene-dir", "plan {I}/task-scene-dir.toml --scene wall -o {O}/p.npz", "dir.json"),
    cli("plan-task-scene-pipe", "plan {I}/task-scene-pipe.toml --scene wall -o {O}/p.npz", "not a regular file",
        proc=True),
    cli("tasks-constraint-untyped", "tasks {I}/task-constraint-untyped.toml", "type"),
    cli("tasks-no-constraints", "tasks {I}/task-no-constraints.toml", "constraints"),
    cli("tasks-description-number", "tasks {I}/task-description-number.toml", "description"),
    cli("tasks-planner-nan", "tasks {I}/task-planner-nan.toml", "range"),
    cli("tasks-planner-inf", "tasks {I}/task-planner-inf.toml", "range"),
    cli("tasks-planner-huge", "tasks {I}/task-planner-huge.toml", "pose", code=0),
    cli("tasks-robot-dir", "tasks {I}/task-robot-dir.toml", "robot"),
    cli("tasks-robot-missing", "tasks {I}/task-robot-missing.toml", "such.urdf"),
    cli("tasks-robot-pipe", "tasks {I}/task-robot-pipe.toml", "pipe", proc=True),
    cli("tasks-srdf-pipe", "tasks {I}/task-srdf-pipe.toml", "pipe", proc=True),
    cli("tasks-axes-unknown", "tasks {I}/task-axes-unknown.toml", "position_axes"),
    cli("tasks-axes-empty", "tasks {I}/task-axes-empty.toml", "pose needs at least one of position_axes"),
    cli("tasks-deep", "tasks {I}/task-deep.toml", "task-deep.toml"),
    cli("tasks-base-bounds-fixed", "tasks {I}/task-base-bounds-fixed.toml", "base_bounds"),
    cli("tasks-floating-panda", "tasks {I}/task-floating-panda.toml", "13 joints"),
    cli("tasks-lock-group-joint", "tasks {I}/task-lock-group-joint.toml", "panda_joint1", "planning group",
        "cannot be locked"),
    cli("tasks-tolerance-huge", "tasks {I}/task-tolerance-huge.toml", "position_tolerance"),
    cli("tasks-binary", "tasks {I}/task-binary.toml", "task-binary.toml"),
    cli("tasks-json-suffix", "tasks {I}/task.json", "pose", code=0),
    cli("tasks-pipe", "tasks {I}/pipe.toml", "pipe.toml", proc=True),
    cli("tasks-dir", "tasks {I}/dir.toml", "directory"),
    cli("tasks-empty", "tasks {I}/empty", "empty"),
    # user constraint code that fails: one line naming the module and the exception
    cli("user-import-raises", f"tasks {_user('imp_raises')}", "imp_raises", "ZeroDivisionError"),
    cli("user-import-syntax", f"tasks {_user('imp_syntax')}", "imp_syntax", "SyntaxError"),
    cli("user-init-raises", f"tasks {_user('init_raises')}", "init_raises", "ValueError", "no frame for you"),
    cli("user-residual-raises", f"collect {_user('res_raises')} --per-condition 5 -o {{O}}/x.npz", "res_raises",
        "ZeroDivisionError"),
    cli("user-residual-nan", f"collect {_user('res_nan')} --per-condition 5 -o {{O}}/x.npz", "res_nan", "NaN"),
    cli("user-residual-shape", f"collect {_user('res_shape')} --per-condition 5 -o {{O}}/x.npz", "res_shape", "shape"),
    cli("user-jacobian-raises", f"collect {_user('jac_raises')} --per-condition 5 -o {{O}}/x.npz", "jac_raises",
        "KeyError"),
    cli("user-not-a-class", f"tasks {_user('not_class')}", "not_class"),
    cli("user-exits", f"tasks {_user('exits')}", "exits", "called exit(3)"),
    # path files
    cli("trajectory-one-waypoint", "trajectory {I}/path-one.npz -o {O}/t.json", "1 waypoints", code=0),
    cli("trajectory-still-path", "trajectory {I}/path-still.npz -o {O}/t.json", "0.00 s", code=0),
    cli("trajectory-outside-limits", "trajectory {I}/path-outside-limits.npz -o {O}/t.json", "invalid"),
    cli("trajectory-off-manifold", "trajectory {I}/path-offmanifold.npz -o {O}/t.json", "invalid"),
    cli("trajectory-int-path", "trajectory {I}/path-int.npz -o {O}/t.json", "float64 array of finite numbers"),
    cli("trajectory-3d-path", "trajectory {I}/path-3d.npz -o {O}/t.json", "path-3d.npz"),
    cli("trajectory-condition-nan", "trajectory {I}/path-condition-nan.npz -o {O}/t.json", "condition"),
    cli("trajectory-condition-str", "trajectory {I}/path-condition-str.npz -o {O}/t.json", "condition"),
    cli("trajectory-scene-bad", "trajectory {I}/path-scene-bad.npz -o {O}/t.json", "obstacle 0"),
    cli("trajectory-tolerance-widened", "trajectory {I}/path-tolerance.npz -o {O}/t.json", "tolerance"),
    cli("trajectory-robot-other", "trajectory {I}/path-robot-other.npz -o {O}/t.json", "pr2"),
    cli("trajectory-task-file-shadow", "trajectory {I}/path-task-file.npz -o {O}/t.json", "trajectory", code=0),
    cli("trajectory-pipe", "trajectory {I}/pipe.npz -o {O}/t.json", "pipe.npz", proc=True),
    cli("trajectory-output-symlink-input", "trajectory {I}/path.npz -o {I}/evil/../link.npz", "link.npz"),
    cli("view-export-pipe", "view {I}/pipe.npz --export {O}/v.html", "pipe.npz", proc=True),
    cli("view-export-dir", "view {I}/dir.npz --export {O}/v.html", "dir.npz"),
    cli("view-export-txt", "view {I}/empty --export {O}/v.html", "empty"),
    cli("view-export-over-input", "view {I}/path.npz --export {I}/path.npz", "path.npz"),
    cli("view-export-task-file-shadow", "view {I}/path-task-file.npz --export {O}/v.html", "wrote", code=0),
    cli("view-snapshots-dataset", "view {I}/data.npz --snapshots {O}/v.png", "path file"),
    # robots and demo
    cli("robots-pipe", "robots {I}/pipe", "pipe", proc=True),
    cli("robots-dir", "robots {I}", "robot"),
    cli("robots-not-urdf", "robots {I}/empty", "empty"),
    cli("robots-srdf-pipe", "robots panda --srdf {I}/pipe", "pipe", proc=True),
    cli("robots-srdf-missing", "robots panda --srdf {I}/none.srdf", "none.srdf"),
    cli("demo-unicode-name", "demo pöse -o {O}/d", "pöse"),
    cli("demo-output-dotdot-input", "demo -o {I}/model/..", "no demo wrote"),
    # conflicting options, resume with changed arguments
    cli("train-auto-resume-settings", "train {I}/data.npz --resume --set hidden=[8] -o {O}/m", "--model"),
    cli("bench-plan-duplicate-labels", "bench plan pose --scene wall -m a=rrtconnect@project -m a=rrtconnect@uniform "
        "-o {O}/b", "'a'"),
    cli("bench-plan-baseline-empty", "bench plan pose --scene wall -m rrtconnect@project --baseline '' -o {O}/b",
        "baseline"),
    cli("bench-plan-physics-fixed", "bench plan pose --scene wall -m rrtconnect@project --physics -o {O}/b",
        "--physics"),
    cli("bench-plan-local-unknown", "bench plan pose --scene wall -m rrtconnect:zigzag@project -o {O}/b", "zigzag"),
    cli("bench-plan-sampler-empty", "bench plan pose --scene wall -m rrtconnect@ -o {O}/b", "no sampler"),
    cli("bench-plan-label-unicode", "bench plan pose --scene wall -m ü=rrtconnect@project -o {O}/b", "ü"),
    # the Python API
    api("api-get-task-robot-int", lambda I, O: get_task("pose", 5), "5"),
    api("api-load-task-pipe", lambda I, O: load_task_file(I / "dir.toml"), "directory"),
    api("api-dataset-nan-rows", lambda I, O: Dataset(np.full((3, 7), np.nan), np.zeros((3, 1)), {}).save(O / "d.npz"),
        "NaN"),
    api("api-cvae-hidden-huge", lambda I, O: CVAE(hidden=[10 ** 9]).fit(Dataset.load(I / "data.npz"), epochs=1,
                                                                     progress=False), "hidden"),
    api("api-load-model-code", lambda I, O: load_model(I / "model-kind-code"), "os:system"),
    api("api-collect-huge", lambda I, O: collect(get_task("pose", "panda"), 10 ** 12, seed=0, progress=False),
        "rows"),
]


def _run_query(**kw):
    from manifoldgen.query import run_query
    from manifoldgen.scene import get_scene
    task = get_task("pose", "panda")
    return run_query(task, get_scene(task, "wall"), "project", "rrtconnect", **{"seed": 0, **kw})


def _sampler(I, O):
    from manifoldgen import api as mg
    task = get_task("pose", "panda")
    return mg.sampler(task, mg.load_scene(task, "wall"), "project")


CASES += [
    cli("user-inequality-nan", f"plan {_user('ineq_nan')} --scene open --time 3 --no-picture -o {{O}}/p.npz",
        "ineq_nan", "inequality", "NaN", "fix its inequality()"),
    cli("user-inequality-not-an-array", f"plan {_user('ineq_int')} --scene open --time 3 --no-picture -o {{O}}/p.npz",
        "ineq_int", "has shape ()", "fix its inequality()"),
    cli("plan-resolution-tiny", "plan pose --scene wall --time 3 --no-picture --set resolution=1e-12 -o {O}/p.npz",
        "resolution", "1e-12", "[0.0001, 10]"),
    cli("plan-set-range-nan", "plan pose --scene wall --time 3 --no-picture --set range=nan -o {O}/p.npz",
        "range", "finite", "nan"),
    cli("plan-shortcut-negative", "plan pose --scene wall --time 3 --no-picture --set shortcut=-5 -o {O}/p.npz",
        "shortcut", "-5", "whole number"),
    api("api-plan-settings-nan", lambda I, O: _run_query(time_limit=2.0, settings={"range": float("nan")}),
        "range", "nan"),
    api("api-plan-settings-string", lambda I, O: _run_query(time_limit=2.0, settings={"range": "big"}),
        "range", "'big'"),
    api("api-plan-smooth-string", lambda I, O: __import__("manifoldgen").plan(
        get_task("pose", "panda"), "wall", smooth="no", time_limit=2.0), "smooth", "'no'"),
    cli("tasks-user-residual-raises", f"tasks {_user('res_raises')}", "user code", "res_raises.py, line",
        "ZeroDivisionError"),
    cli("tasks-user-init-raises", f"tasks {_user('init_raises')}", "user code", "init_raises.py, line", "ValueError"),
    cli("tasks-user-import-raises", f"tasks {_user('imp_raises')}", "user code", "imp_raises.py, line 1",
        "ZeroDivisionError"),
    cli("plan-model-decoder-noise", "plan pose --scene wall --time 3 --no-picture "
        "--sampler model:{I}/model-decoder-noise -o {O}/p.npz", "'decoder' entry does not fit its weights", "restore"),
    cli("plan-model-decoder-steps", "plan pose --scene wall --time 3 --no-picture "
        "--sampler model:{I}/model-decoder-steps -o {O}/p.npz", "steps [0, 1000]"),
    cli("trajectory-dt-coarse", "trajectory {I}/path.npz --dt 5 -o {O}/t.csv", "straight motion", "smaller --dt"),
    api("api-sample-many-negative", lambda I, O: _sampler(I, O).sample_many(-1), "whole number", "-1"),
    api("api-sample-many-fraction", lambda I, O: _sampler(I, O).sample_many(2.5), "whole number", "2.5"),
    api("api-run-query-time-nan", lambda I, O: _run_query(time_limit=float("nan")), "time"),
    api("api-run-query-time-negative", lambda I, O: _run_query(time_limit=-1.0), "time"),
    api("api-run-query-time-inf", lambda I, O: _run_query(time_limit=float("inf")), "time"),
]


def test_the_table_is_large_enough():
    assert len(CASES) >= 150 and len({c.id for c in CASES}) == len(CASES)


def _watched(args: list[str], inputs: Path):
    """``runner.invoke(args)`` in a thread; after 30 s without an answer, every pipe of ``inputs`` is opened for
    writing and closed (a reader blocked on one gets end-of-file) and the case fails as a hang."""
    done = []
    thread = threading.Thread(target=lambda: done.append(runner.invoke(app, args, terminal_width=400)), daemon=True)
    thread.start()
    thread.join(30)
    if thread.is_alive():
        for pipe in [p for p in inputs.rglob("*") if p.is_fifo() and not p.is_symlink()]:
            with contextlib.suppress(OSError):
                os.close(os.open(pipe, os.O_WRONLY | os.O_NONBLOCK))
        thread.join(30)
        pytest.fail("hung: no answer in 30 s")
    return done[0]


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_hostile(case, inputs, tmp_path):
    before = _digest(inputs)
    out = tmp_path / "out"
    out.mkdir()
    if case.args is not None:
        args = [a.format(I=inputs, O=out) for a in case.args]
        result = _watched(args, inputs) if case.proc else runner.invoke(app, args, terminal_width=400)
        code, output = result.exit_code, result.output
        if result.exception is not None and not isinstance(result.exception, SystemExit):
            pytest.fail(f"raised {type(result.exception).__name__}: {result.exception}")
        assert "Traceback" not in output, output
        assert code == case.code, output
        if code == 2:
            errors = [line for line in output.splitlines() if line.startswith("error: ")]
            assert len(errors) == 1, output
            message = errors[0]
            assert not [p for p in out.rglob("*") if p.is_file()], "a refused command wrote files"
        else:
            message = output
    else:
        with pytest.raises(ManifoldgenError) as info:
            case.call(inputs, out)
        message = str(info.value)
        assert "\n" not in message
    for word in case.needle:
        assert word in message, message
    assert not (inputs / MARK).exists(), "a data file ran code"
    assert _digest(inputs) == before, "an input file changed"
    leftovers = [p.name for p in out.rglob("*") if p.name.endswith((".tmp", ".partial"))]
    assert not leftovers, leftovers
