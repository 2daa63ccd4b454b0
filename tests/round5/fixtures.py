#!/usr/bin/env python3
"""Make the inputs of the hostile round's table (tests/test_hostile_round5_table.py) in $IN with the manifoldgen of
$CLONE (the repository, with its .venv):  CLONE=REPO IN=FOLDER REPO/.venv/bin/python fixtures.py"""
import json, os, shutil, subprocess, sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/: the refusal tables' helpers
from refusals import reseal  # noqa: E402

CLONE = Path(os.environ.get("CLONE", Path(__file__).resolve().parents[2]))
IN = Path(os.environ["IN"])
MG = str(CLONE / ".venv/bin/manifoldgen")
ENV = {**os.environ, "OMP_NUM_THREADS": "1"}
BUILTIN = CLONE / "src/manifoldgen/tasks"


def mg(*args):
    subprocess.run([MG, *map(str, args)], check=True, env=ENV, cwd=IN, stdout=subprocess.DEVNULL)


def load(p):
    with np.load(p, allow_pickle=False) as f:
        arrays = {k: f[k] for k in f.files}
    return json.loads(str(arrays.pop("meta"))), arrays


def save(p, meta, arrays):
    np.savez(p, meta=np.array(json.dumps(meta)), **arrays)


def edit_npz(src, dst, fn=None, afn=None):
    meta, arrays = load(IN / src)
    if fn:
        r = fn(meta)
        meta = r if isinstance(r, dict) else meta
    if afn:
        r = afn(arrays)
        arrays = r if isinstance(r, dict) else arrays
    save(IN / dst, meta, arrays)


def setp(*keys, value):
    def fn(d):
        for k in keys[:-1]:
            d = d[k]
        d[keys[-1]] = value
    return fn


def drop(*keys):
    def fn(d):
        for k in keys[:-1]:
            d = d[k]
        d.pop(keys[-1])
    return fn


def model_copy(name, edit=None, weights=None):
    shutil.copytree(IN / "model", IN / name)
    reseal(IN / name, edit, weights)


def task_text(**replace):
    text = (BUILTIN / "pose-panda.toml").read_text().replace('"scenes/', f'"{BUILTIN}/scenes/')
    for old, new in replace.items():
        assert old in text, old
        text = text.replace(old, new)
    return text


def main():
    if IN.exists():
        shutil.rmtree(IN)
    IN.mkdir(parents=True)
    # --- the base files
    mg("collect", "pose", "--per-condition", 50, "--seed", 0, "-o", "data.npz")
    mg("train", "data.npz", "--model", "cvae", "--epochs", 2, "--set", "hidden=[32]", "-o", "model")
    mg("plan", "pose", "--scene", "wall", "--time", 10, "-o", "path.npz")
    mg("plan", "pose", "--scene", "wall", "--time", 10, "--no-picture", "--roadmap", "rm.npz", "-o", "p2.npz")
    mg("bench", "plan", "pose", "--scene", "wall", "--runs", 1, "--time", 5, "-m", "rrtconnect@project", "-o", "bench")
    mg("sample", "model", "--condition", 0.45, "-n", 50, "-o", "samples.npz")
    import fixtures_more
    fixtures_more.make(sys.modules[__name__])
    print("inputs in", IN)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).parent))
    main()
