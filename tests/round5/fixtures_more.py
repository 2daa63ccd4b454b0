"""The edited and hand-made inputs of the round-5 cases (called by fixtures.py with its helpers as ``f``)."""
import json, shutil, subprocess, zipfile

import numpy as np


def make(f):
    IN, BUILTIN = f.IN, f.BUILTIN
    setp, drop, edit_npz = f.setp, f.drop, f.edit_npz
    # ---------------------------------------------------------------- path files (from path.npz)
    for name, fn in {
        "pv-range-neg": setp("planner_settings", "range", value=-1.0),
        "pv-valid-false": setp("validation", "valid", value=False),
        "pv-solved-false": setp("result", "solved", value=False),
        "pv-waypoints": setp("result", "waypoints", value=999),
        "pv-locked": setp("locked", value={"panda_finger_joint1": 0.5, "panda_finger_joint2": 0.0}),
        "pv-constraint": setp("constraint", "rotation", value=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
        "pv-fb-str": setp("floating_base", value="no"),
        "pv-kind-missing": drop("kind"),
        "pv-res-tiny": setp("validation", "resolution", value=1e-300),
        "pv-local-zig": setp("local", value="zigzag"),
        "pv-extras-nan": setp("result", "extras", value={"nested": {"a": float("nan")}}),
        "pv-ver-float": setp("format_version", value=2.0),
    }.items():
        edit_npz("path.npz", f"{name}.npz", fn)

    def dense(a, k=200):
        p = a["path"]
        out = [p[0]] + [p[i] * (1 - t) + p[i + 1] * t for i in range(len(p) - 1) for t in np.linspace(0, 1, k + 1)[1:]]
        a["path"] = np.array(out)
    edit_npz("path.npz", "p-dense200.npz", afn=dense)
    edit_npz("path.npz", "p-dup100k.npz",
             afn=lambda a: a.update(path=np.concatenate([np.repeat(a["path"][:1], 100000, 0), a["path"]])))
    # a 3 GB array of zeros compressed to 13 MB beside the rows of a dataset, and beside a path (the fastest
    # compression level: 5 s each, against 17 s for a 3 MB file at the default level)
    for src, dst in (("data.npz", "bomb-data.npz"), ("path.npz", "bomb-path.npz")):
        shutil.copy(IN / src, IN / dst)
        from numpy.lib import format as fmt
        n = 375_000_000
        with zipfile.ZipFile(IN / dst, "a", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as z:
            with z.open("junk.npy", "w", force_zip64=True) as out:
                fmt.write_array_header_1_0(out, {"descr": "<f8", "fortran_order": False, "shape": (n,)})
                chunk = bytes(8 * 1_000_000)
                for _ in range(n // 1_000_000):
                    out.write(chunk)
    # ---------------------------------------------------------------- roadmap files (from rm.npz)
    edit_npz("rm.npz", "rm-extra.npz", afn=lambda a: a.update(junk=np.zeros(3)))
    edit_npz("rm.npz", "rm-reach-str.npz", setp("reach", value="far"))

    def reversed_copies(a):
        e = a["edges"]
        a["edges"] = np.concatenate([e, e[:, ::-1]])
        a["lengths"] = np.concatenate([a["lengths"], a["lengths"]])
    edit_npz("rm.npz", "rm-dup-edges.npz", afn=reversed_copies)
    edit_npz("rm.npz", "rm-len32.npz", afn=lambda a: a.update(lengths=a["lengths"].astype(np.float32)))

    def emptied(a):
        for k in ("nodes", "edges", "lengths"):
            a[k] = a[k][:0]
    edit_npz("rm.npz", "rm-empty.npz", afn=emptied)

    def moved(a):
        n = a["nodes"].copy()
        n[5, 0] += 3.0
        a["nodes"] = n
        e = a["edges"]
        a["lengths"] = np.linalg.norm(n[e[:, 1]] - n[e[:, 0]], axis=1)
    edit_npz("rm.npz", "rm-node-moved.npz", afn=moved)
    # ---------------------------------------------------------------- datasets (from data.npz)
    edit_npz("data.npz", "d-perc-wrong.npz", setp("per_condition", value=7))
    edit_npz("data.npz", "d-anchor-label-int.npz",
             lambda m: m.update(anchors=[dict(m["anchors"][0], label=5)] + m["anchors"][1:]))
    edit_npz("data.npz", "d-method-num.npz", setp("method", value=42))
    edit_npz("data.npz", "d-fb-str.npz", setp("floating_base", value="no"))
    edit_npz("data.npz", "d-two-rows.npz", afn=lambda a: a.update(q=a["q"][[0, 100]], y=a["y"][[0, 100]]))
    edit_npz("data.npz", "d-seed-mismatch.npz", setp("seed", value=123))
    edit_npz("data.npz", "d-task-file-elsewhere.npz", setp("task", "task_file", value="/etc/passwd"))
    # ---------------------------------------------------------------- models (resealed: checksums recomputed)
    f.model_copy("m-lr-str", edit=lambda d: d["config"].update(lr="fast"))
    f.model_copy("m-beta-neg", edit=lambda d: d["config"].update(beta=-5.0))
    f.model_copy("m-extra-tensor", weights=lambda w: w.update(junk=np.zeros(3, np.float32)))
    f.model_copy("m-mix-half", edit=lambda d: d.update(mix=0.5))
    for name, doc in (("bm-empty", "{}"), ("bm-notjson", "not json"), ("bm-list", "[]")):
        (IN / name).mkdir()
        (IN / name / "model.json").write_text(doc)
    # ---------------------------------------------------------------- a balance path (centauro), for physics
    f.mg("plan", "balance", "--scene", "reach", "--time", 30, "--no-picture", "-o", "bal.npz")
    # ---------------------------------------------------------------- an automatic training and a sweep, to edit
    f.mg("train", "data.npz", "--epochs", 1, "-o", "auto")
    f.mg("sweep", "data.npz", "--model", "cvae", "--epochs", 1, "-o", "sweep")
    # a checkpoint of an interrupted training (killed after a few epochs)
    subprocess.run(["timeout", "-s", "KILL", "6", f.MG, "train", "data.npz", "--model", "cvae", "--epochs", "100000",
                    "--set", "hidden=[8]", "--set", "patience=100000", "-o", "ck"], cwd=IN, env=f.ENV,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    assert (IN / "ck" / "checkpoint.safetensors").is_file(), "the interrupted training left no checkpoint"
    (IN / "ck.lock").unlink(missing_ok=True)  # the killed writer's lock
    import safetensors.numpy
    blob = (IN / "ck" / "checkpoint.safetensors").read_bytes()
    size = int.from_bytes(blob[:8], "little")
    header_meta = json.loads(blob[8:8 + size])["__metadata__"]
    arrays = safetensors.numpy.load(blob)
    for name, edit in (("ck-norng", lambda a, s: a.pop("rng")), ("ck-bad-str", lambda a, s: s.update(bad="x")),
                       ("ck-no-opt", lambda a, s: s.pop("optimizers")),
                       ("ck-nomodel", lambda a, s: [a.pop(k) for k in list(a) if k.startswith("model.")])):
        shutil.copytree(IN / "ck", IN / name)
        a, s = dict(arrays), json.loads(header_meta["state"])
        edit(a, s)
        (IN / name / "checkpoint.safetensors").write_bytes(
            safetensors.numpy.save(a, metadata={**header_meta, "state": json.dumps(s)}))
    # ---------------------------------------------------------------- task files
    tasks = IN / "tasks"
    tasks.mkdir()
    for name, replace in {
        "home-str": {"home = [0.0, -0.785398, 0.0, -2.35619, 0.0, 1.5707, 0.785398]":
                     'home = ["0.0", "-0.785398", "0.0", "-2.35619", "0.0", "1.5707", "0.785398"]'},
        "home-bool": {"home = [0.0, -0.785398, 0.0, -2.35619, 0.0, 1.5707, 0.785398]":
                      "home = [true, false, true, false, true, true, false]"},
        "homec-str": {"home_condition = [0.45]": 'home_condition = ["0.45"]'},
        "homec-nested": {"home_condition = [0.45]": "home_condition = [[0.45]]"},
        "name-empty": {'name = "pose"': 'name = ""'},
        "axes-dup": {'position_axes = ["z"]': 'position_axes = ["z", "z"]'},
        "default-str": {"default = true ": 'default = "yes" '},
        "robot-empty": {'robot = "panda" ': 'robot = "" '},
        "srdf-empty": {'robot = "panda" ': 'robot = "panda"\nsrdf = ""\n'},
        "values-3col": {"values = [[0.2], [0.3], [0.4], [0.5], [0.6], [0.7]]": "values = [[0.3, 0.1, 0.1], [0.5, 0.1, 0.1]]"},
        "no-axes": {'position_axes = ["z"]': 'position_axes = []\norientation_axes = []',
                    "values = [[0.2], [0.3], [0.4], [0.5], [0.6], [0.7]]": "values = []",
                    "home_condition = [0.45]": ""},
    }.items():
        (tasks / f"{name}.toml").write_text(f.task_text(**replace))
    base = f.task_text()
    for name, table in {
        "planner-core": '\n[planner]\ncore = "gpu"\n',
        "planner-resolution": "\n[planner]\nresolution = 10.0\n",
        "att-touch": '\n[attached]\nname = "cup"\ntype = "box"\nattached_to = "panda_hand_tcp"\nsize = [0.05, 0.05, 0.05]\n'
                     'pose = { position = [0.0, 0.0, 0.1] }\ntouch_links = ["no_such_link"]\n',
        "att-frame": '\n[attached]\nname = "cup"\ntype = "box"\nattached_to = "nowhere"\nsize = [0.05, 0.05, 0.05]\n'
                     'pose = { position = [0.0, 0.0, 0.1] }\n',
        "att-huge": '\n[attached]\nname = "cup"\ntype = "sphere"\nattached_to = "panda_hand_tcp"\nradius = 1e6\n'
                    'pose = { position = [0.0, 0.0, 0.1] }\n',
        "att-mesh": '\n[attached]\nname = "cup"\ntype = "mesh"\nattached_to = "panda_hand_tcp"\nmesh = "/etc/passwd"\n'
                    'scale = [1.0, 1.0, 1.0]\npose = { position = [0.0, 0.0, 0.1] }\n',
    }.items():
        (tasks / f"{name}.toml").write_text(base + table)
    head = ('name = "t"\nrobot = "panda"\ngroup = ["panda_joint1", "panda_joint2", "panda_joint3", "panda_joint4", '
            '"panda_joint5", "panda_joint6", "panda_joint7"]\n[[constraints]]\n')
    down = "rotation = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]\n"
    for name, body in {
        "orient-zero-axis": 'type = "orientation"\nframe = "panda_hand_tcp"\naxis = [0.0, 0.0, 0.0]\n',
        "orient-zero-dir": 'type = "orientation"\nframe = "panda_hand_tcp"\ndirection = [0.0, 0.0, 0.0]\n',
        "plane-dependent": 'type = "plane"\nframe = "panda_hand_tcp"\nnormals = [[0.0, 0.0, 1.0], [0.0, 0.0, 2.0]]\n'
                           'values = [[0.3, 0.6], [0.4, 0.8]]\n',
        "plane-zero": 'type = "plane"\nframe = "panda_hand_tcp"\nnormals = [[0.0, 0.0, 0.0]]\nvalues = [[0.3], [0.4]]\n',
        "sphere-center-nan": 'type = "sphere"\nframe = "panda_hand_tcp"\ncenter = [nan, 0.0, 0.0]\nvalues = [[0.5], [0.6]]\n',
        "sphere-neg-radius": 'type = "sphere"\nframe = "panda_hand_tcp"\nvalues = [[-0.5], [-0.6]]\n',
        "jl-cols": 'type = "joint_linear"\ncoefficients = [[1.0, 1.0]]\nvalues = [[0.0], [0.5]]\n',
        "jl-int": 'type = "joint_linear"\ncoefficients = [[1, 1, 0, 0, 0, 0, 0]]\nvalues = [[0], [1]]\n',
        "cc-same": 'type = "closed_chain"\nframe_a = "panda_hand_tcp"\nframe_b = "panda_hand_tcp"\n'
                   'rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\nvalues = [[0.0], [0.1]]\n',
        "rot-zero-axis": f'type = "rotation"\nframe = "panda_hand_tcp"\n{down}axis = [0.0, 0.0, 0.0]\nvalues = [[0.0], [0.5]]\n',
        "pose-tol-tiny": f'type = "pose"\nframe = "panda_hand_tcp"\n{down}values = [[0.3], [0.5]]\nposition_tolerance = 1e-300\n',
        "pose-rot-det-neg": 'type = "pose"\nframe = "panda_hand_tcp"\n'
                            'rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]\nvalues = [[0.3], [0.5]]\n',
        "balance-panda": 'type = "balance"\nfeet = ["panda_hand_tcp"]\nbase_frame = "panda_link0"\nvalues = [[0.3], [0.5]]\n',
    }.items():
        (tasks / f"{name}.toml").write_text(head + body)

    def values(n, lo, hi):
        return "[" + ", ".join(f"[{lo + (hi - lo) * i / (n - 1):.6f}]" for i in range(n)) + "]"
    grid = head.replace("[[constraints]]\n", "")
    for normal, lo, hi in (("[0.0, 0.0, 1.0]", 0.2, 0.7), ("[1.0, 0.0, 0.0]", 0.3, 0.6), ("[0.0, 1.0, 0.0]", -0.3, 0.3)):
        grid += (f'[[constraints]]\ntype = "plane"\nframe = "panda_hand_tcp"\nnormals = [{normal}]\n'
                 f"values = {values(300, lo, hi)}\n")
    (tasks / "grid-big.toml").write_text(grid)
    # a URDF whose joint limits are reversed, and its task
    (tasks / "inv2.urdf").write_text(
        '<robot name="inv2"><link name="base"/><link name="l1"/><link name="l2"/>\n'
        '<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>'
        '<limit lower="1.0" upper="-1.0" effort="1" velocity="1"/></joint>\n'
        '<joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.5 0 0"/><axis xyz="0 0 1"/>'
        '<limit lower="-2.0" upper="2.0" effort="1" velocity="1"/></joint></robot>\n')
    (tasks / "inv2.toml").write_text('name = "inv"\nrobot = "inv2.urdf"\n[[constraints]]\ntype = "joint_linear"\n'
                                     'coefficients = [[1.0, 1.0]]\nvalues = [[0.0], [0.5]]\n')
    (tasks / "broken.urdf").write_text('<robot name="x"><link name="a"/>\n')
    (tasks / "nojoint.urdf").write_text('<robot name="x"><link name="a"/></robot>\n')
    lol = "".join(f' <!ENTITY lol{i} "{("&lol%d;" % (i - 1)) * 10}">\n' for i in range(1, 9))
    (tasks / "laughs.srdf").write_text('<?xml version="1.0"?>\n<!DOCTYPE lolz [\n <!ENTITY lol0 "lollollollol">\n'
                                       + lol + ']>\n<robot name="panda"><group name="&lol8;"/></robot>\n')
    # ---------------------------------------------------------------- user constraint modules (xarm7)
    user = IN / "user"
    user.mkdir()
    module = '''import numpy as np
from manifoldgen.constraints import Condition, Constraint, array_namespace

TOL = 0.01
VALUES = [[0.3], [0.4], [0.5]]
NAMES, UNITS = ("x",), ("m",)
{extra}

class Tool(Constraint):
    def __init__(self, robot, frame="link_eef"):
        self.robot, self.frame = robot, frame
        self.condition = Condition(NAMES, UNITS, np.asarray(VALUES, float))
        self.tolerance = np.full(3, TOL) if np.isscalar(TOL) else np.asarray(TOL, float)

    def residual(self, q, y):
        q, y = self.batch(q, y)
        p, R = self.robot.frame_pose(q, self.frame)
        return array_namespace(q).concat([p[:, :1] - y, R[:, :2, 2]], axis=1)
'''
    for name, extra in {"u_tol_huge": "TOL = 1e6", "u_tol_zero": "TOL = 0.0", "u_tol_nan": 'TOL = float("nan")',
                        "u_tol_neg": "TOL = -0.01", "u_names_k2": 'NAMES, UNITS = ("x", "y"), ("m", "m")',
                        "u_vals_dup": "VALUES = [[0.3], [0.3]]", "u_vals_empty": "VALUES = []",
                        "u_vals_nan": 'VALUES = [[0.3], [float("nan")]]', "u_ok": ""}.items():
        (user / f"{name}.py").write_text(module.format(extra=extra))
        (user / f"{name}.toml").write_text(
            f'name = "{name}"\nrobot = "xarm7"\ngroup = ["joint1", "joint2", "joint3", "joint4", "joint5", "joint6", '
            f'"joint7"]\n[[constraints]]\ntype = "{name}:Tool"\nframe = "link_eef"\n')
    # ---------------------------------------------------------------- scene files (from the panda wall)
    scenes = IN / "scenes"
    scenes.mkdir()
    wall = json.loads((BUILTIN / "scenes" / "panda-wall.json").read_text())

    def scene(name, fn):
        d = json.loads(json.dumps(wall))
        fn(d)
        (scenes / f"{name}.json").write_text(json.dumps(d))
    far = {"position": [2, 2, 2]}
    scene("cond-nested", lambda d: d.update(condition=[[0.5]]))
    scene("cond-two", lambda d: d.update(condition=[0.5, 0.5]))
    scene("dup-names", lambda d: d["obstacles"][1].update(name="wall_left"))
    scene("name-empty", lambda d: d["obstacles"][0].update(name=""))
    scene("quat-norm2", lambda d: d["obstacles"][0]["pose"].update(quaternion=[0, 0, 0, 2.0]))
    scene("cyl-nolength", lambda d: d["obstacles"].append({"name": "c", "type": "cylinder", "radius": 0.05, "pose": far}))
    scene("cyl-zero", lambda d: d["obstacles"].append({"name": "c", "type": "cylinder", "radius": 0.05, "length": 0.0,
                                                       "pose": far}))
    scene("target-quat-norm", lambda d: d.update(goal={"position": [0.4, 0.0, 0.5], "quaternion": [2.0, 0, 0, 0]}))
    scene("target-extra", lambda d: d.update(goal={"position": [0.4, 0.0, 0.5], "quaternion": [1.0, 0, 0, 0],
                                                  "frame": "panda_hand_tcp", "tolerance": 5}))
    scene("start-eq-goal", lambda d: d.update(goal=d["start"]))
    scene("obst-pose-missing", lambda d: d["obstacles"][0].pop("pose"))
    scene("many-1000", lambda d: d.update(obstacles=[
        {"name": f"b{i}", "type": "box", "size": [0.01, 0.01, 0.01],
         "pose": {"position": [5 + 0.02 * (i % 30), 5 + 0.02 * (i // 30), 0]}} for i in range(1000)]))
    scene("attached-str", lambda d: d.update(attached="none"))
    scene("mesh-devzero", lambda d: d["obstacles"].append({"name": "m", "type": "mesh", "mesh": "/dev/zero",
                                                           "scale": [1, 1, 1], "pose": far}))
    scene("mesh-proc", lambda d: d["obstacles"].append({"name": "m", "type": "mesh", "mesh": "/proc/self/environ",
                                                        "scale": [1, 1, 1], "pose": far}))
    (scenes / "deep.json").write_text('{"obstacles": ' + "[" * 100000 + "]" * 100000 + "}")
    (scenes / "dupkey.json").write_text('{"obstacles": [], "robot": "panda", "start": [0,0,0,0,0,0,0], "goal": '
                                        '[0,0,0,0,0,0,0], "condition": [0.5], "format_version": 1, "name": "x", '
                                        '"obstacles": [1]}')
    (IN / "cfg-latent-str.toml").write_text('latent = "3"\n')
    # ---------------------------------------------------------------- files naming user code (a module that leaves a mark)
    (IN / "evil").mkdir()
    (IN / "evil" / "evilmod.py").write_text(
        "import os, pathlib\npathlib.Path(os.environ.get('O', '.'), 'PWNED').write_text('imported')\nclass C:\n    pass\n")

    def code(m):
        m["task"]["constraint"]["type"] = "evilmod:C"
        m["constraint"]["type"] = "evilmod:C"
    edit_npz("data.npz", "d-code.npz", code)
    edit_npz("path.npz", "p-code.npz", code)
    edit_npz("samples.npz", "s-code.npz", code)
    edit_npz("rm.npz", "r-code.npz", code)
    edit_npz("bal.npz", "bal-code.npz", lambda m: m["task"]["constraint"].update(type="evilmod:C") or
             m["constraint"].update(type="evilmod:C"))
    edit_npz("path.npz", "p-planner-code.npz", setp("planner", value="evilmod:C"))
    f.model_copy("m-code", edit=lambda d: (d["meta"]["task"]["constraint"].update(type="evilmod:C"),
                                           d["meta"]["constraint"].update(type="evilmod:C")))
