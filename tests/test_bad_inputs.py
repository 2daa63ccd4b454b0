"""The bad-input table: every command and the Python API refuse bad input with one line naming the
offending value (exit code 2 on the command line), no traceback, no input file changed and nothing
half-written left behind."""

from __future__ import annotations

import errno
import io
import json
import os
import shutil

import numpy as np
import pytest

from manifoldgen.bench.sampling import run_sampling_bench
from manifoldgen.data import collect
from manifoldgen.dataset import Dataset
from manifoldgen.io import atomic_write_text, check_output_path
from manifoldgen.models import CVAE, load_model
from manifoldgen.models.base import document_checksum
from manifoldgen.sampling import sample_to_file
from manifoldgen.query import run_query
from manifoldgen.scene import Scene, get_scene
from manifoldgen.specs import parse_spec
from manifoldgen.tasks import BUILTIN_DIR, get_task, load_task_file, task_from_meta
from refusals import api, cli, refused_cleanly

TINY = {"hidden": [8], "batch": 8, "epochs": 1, "patience": 5}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, panda_task, planned_path):
    """A folder of small input files, made once: dataset, model (and damaged copies), scenes, task file, path."""
    root = tmp_path_factory.mktemp("inputs")
    data = collect(panda_task, 12, seed=0, conditions=[[0.3], [0.5]], progress=False)
    data.save(root / "data.npz")
    Dataset(data.q[:12], data.y[:12], data.meta).save(root / "single.npz")
    Dataset(data.q, data.y, {**data.meta, "joints": data.meta["joints"][::-1]}).save(root / "reversed.npz")
    CVAE(**TINY).fit(data, seed=0, progress=False, out=root / "model")
    doc = json.loads((root / "model" / "model.json").read_text())
    for name, edit in (("edited", lambda d: d["normalisation"]["q_mean"].__setitem__(0, 0.5)),
                       ("widened", lambda d: d["normalisation"]["y_high"].__setitem__(0, 2.0)),
                       ("version1", lambda d: d.update(format_version=1))):
        shutil.copytree(root / "model", root / name)
        changed = json.loads(json.dumps(doc))
        edit(changed)
        (root / name / "model.json").write_text(json.dumps(changed, indent=1))
    shutil.copytree(root / "model", root / "resigned")  # an edit with a recomputed checksum still meets the checks
    changed = json.loads(json.dumps(doc))
    changed["dims"]["d"] = 6
    changed["sha256"] = document_checksum(changed)
    (root / "resigned" / "model.json").write_text(json.dumps(changed))
    shutil.copytree(root / "model", root / "rehidden")  # config hidden edited, checksum recomputed
    changed = json.loads(json.dumps(doc))
    changed["config"]["hidden"] = [9]
    changed["sha256"] = document_checksum(changed)
    (root / "rehidden" / "model.json").write_text(json.dumps(changed))
    shutil.copytree(root / "model", root / "cut")
    blob = (root / "cut" / "model.safetensors").read_bytes()
    (root / "cut" / "model.safetensors").write_bytes(blob[:len(blob) // 2])
    shutil.copy(BUILTIN_DIR / "pose-panda.toml", root / "task.toml")
    text = (BUILTIN_DIR / "pose-panda.toml").read_text()
    arm = ", ".join(f'"panda_joint{i}"' for i in range(1, 8))
    group = text[text.index("group = ["):text.index("]", text.index("group = [")) + 1]
    for name, joints in (("duplicate", f'"panda_joint1", {arm}'), ("empty", ""),
                         ("mimic", f'{arm}, "panda_finger_joint2"'), ("fixed", f'{arm}, "panda_joint8"')):
        (root / f"{name}.toml").write_text(text.replace(group, f"group = [{joints}]"))
    shutil.copytree(BUILTIN_DIR / "scenes", root / "scenes")
    wall = json.loads((BUILTIN_DIR / "scenes" / "panda-wall.json").read_text())
    (root / "scene.json").write_text(json.dumps(wall))
    (root / "high.json").write_text(json.dumps({**wall, "condition": [0.95]}))  # its start and goal are at 0.5
    crowd = [{"name": f"b{i}", "type": "sphere", "radius": 0.01, "pose": {"position": [3.0 + 0.03 * i, 3.0, 0.0]}}
             for i in range(1001)]
    (root / "crowded.json").write_text(json.dumps({**wall, "obstacles": crowd}))
    (root / "latin1.json").write_bytes(json.dumps(wall).replace("wall_left", "wäll").encode("latin-1"))
    (root / "bad.stl").write_text("solid x\n garbage\nendsolid\n")
    for name, obstacle in (("far", {"type": "box", "size": [0.1, 0.1, 0.1], "pose": {"position": [1e308, 0, 0]}}),
                           ("huge", {"type": "sphere", "radius": 1e300, "pose": {"position": [0, 0, 0]}}),
                           ("mesh", {"type": "mesh", "mesh": str(root / "bad.stl"), "pose": {"position": [2, 0, 0]}}),
                           ("nomesh", {"type": "mesh", "mesh": str(root / "gone.stl"),
                                       "pose": {"position": [2, 0, 0]}})):
        (root / f"{name}.json").write_text(json.dumps({**wall, "obstacles": [obstacle]}))
    (root / "text.npz").write_text("q,y\n1,2\n")
    (root / "bad.toml").write_text("name = [unclosed\n")
    (root / "latin1.toml").write_bytes("name = 'pösé'\n".encode("latin-1"))
    shutil.copy(planned_path("wall"), root / "path.npz")
    os.mkfifo(root / "pipe")  # not a regular file: never replaced by an output
    return root


def _collect(I, O, **kw):
    return collect(get_task("pose", "panda"), 5, out=O / "x.npz", progress=False, **{"seed": 0, **kw})


def _model(I, name="model"):
    return load_model(I / name)


def _sample_to_file(I, O, **kw):
    model = _model(I)
    return sample_to_file(model, task_from_meta(model.meta).constraint, np.array([0.4]),
                          **{"count": 5, "out": O / "s.npz", **kw})


def _plan(**kw):
    task = get_task("pose", "panda")
    return run_query(task, get_scene(task, "wall"), "project", "rrtconnect", **{"seed": 0, "time_limit": 1.0, **kw})


CASES = [
    # collect
    cli("collect-unknown-task", "collect poze -o {O}/x.npz", "poze"),
    cli("collect-unknown-robot", "collect pose --robot ur99 -o {O}/x.npz", "ur99"),
    cli("collect-task-not-for-robot", "collect pose --robot baxter -o {O}/x.npz", "baxter"),
    cli("collect-zero-rows", "collect pose --per-condition 0 -o {O}/x.npz", "got 0"),
    cli("collect-negative-rows", "collect pose --per-condition -3 -o {O}/x.npz", "-3"),
    cli("collect-negative-seed", "collect pose --seed -1 -o {O}/x.npz", "-1"),
    cli("collect-huge-seed", "collect pose --seed 99999999999999 -o {O}/x.npz", "99999999999999"),
    cli("collect-strict-range", "collect pose --per-condition 5 --condition 0.95 --strict -o {O}/x.npz", "0.95"),
    cli("collect-nan-condition", "collect pose --per-condition 5 --condition nan -o {O}/x.npz", "nan"),
    cli("collect-missing-dir", "collect pose -o {O}/nodir/x.npz", "nodir"),
    cli("collect-output-is-dir", "collect pose -o {O}", "is a folder"),
    cli("collect-output-is-pipe", "collect pose -o {I}/pipe", "not a regular file"),
    cli("sample-output-is-pipe", "sample {I}/model --condition 0.4 -o {I}/pipe", "not a regular file"),
    cli("train-dataset-is-a-folder", "train {I} -o {O}/m", "is a directory, not a file"),
    cli("train-dataset-is-a-pipe", "train {I}/pipe -o {O}/m", "is not a regular file (a device, pipe or socket)"),
    cli("sample-model-is-a-file", "sample {I}/pipe --condition 0.4 -o {O}/s.npz",
        "is a device, pipe or socket, not a directory"),
    cli("plan-config-is-a-folder", "plan pose --scene wall --config {I} -o {O}/p.npz",
        "is a directory, not a file"),
    api("api-atomic-over-pipe", lambda I, O: atomic_write_text(I / "pipe", "x"), "not a regular file"),
    cli("bench-sampling-too-few-samples", "bench sampling {I}/model --samples 2 -o {O}/b", "got 2"),
    cli("sample-condition-1e308", "sample {I}/model --condition 1e308 -o {O}/s.npz", "1e+308"),
    cli("collect-output-is-task-file", "collect {I}/task.toml -o {I}/task.toml", "task.toml"),
    cli("collect-group-duplicate", "collect {I}/duplicate.toml -o {O}/x.npz", "'panda_joint1' is 2 times"),
    cli("collect-group-empty", "collect {I}/empty.toml -o {O}/x.npz", "empty planning group"),
    cli("collect-group-mimic", "collect {I}/mimic.toml -o {O}/x.npz", "'panda_finger_joint2'"),
    cli("collect-group-fixed", "collect {I}/fixed.toml -o {O}/x.npz", "'panda_joint8'"),
    cli("collect-markup-in-path", "collect pose -o {O}/a[/]b/x.npz", "a[/]b"),
    cli("collect-missing-task-file", "collect {I}/nothere.toml -o {O}/x.npz", "nothere.toml"),
    cli("collect-bad-toml", "collect {I}/bad.toml -o {O}/x.npz", "bad.toml"),
    cli("collect-not-utf8-toml", "collect {I}/latin1.toml -o {O}/x.npz", "latin1.toml"),
    cli("collect-read-only", "collect pose --per-condition 5 -o {O}/x.npz", "Read-only file system", patch="read_only"),
    cli("collect-disk-full", "collect pose --per-condition 5 -o {O}/x.npz", "No space left", patch="disk_full"),
    # train
    cli("train-missing-dataset", "train {I}/none.npz -o {O}/m", "none.npz"),
    cli("train-text-npz", "train {I}/text.npz -o {O}/m", "text.npz"),
    cli("train-unknown-model", "train {I}/data.npz --model cvea -o {O}/m", "cvea"),
    cli("train-batch-zero", "train {I}/data.npz --model cvae --set batch=0 -o {O}/m", "batch=0"),
    cli("train-negative-lr", "train {I}/data.npz --model cvae --set lr=-1 -o {O}/m", "lr=-1"),
    cli("train-huge-weight", "train {I}/data.npz --model cvae --set beta=1e308 -o {O}/m",
        "beta=1e+308 of model 'cvae' must be a number from 0 to 1e+06"),
    cli("train-huge-lr", "train {I}/data.npz --model cvae --set lr=1e5 -o {O}/m", "lr=100000.0"),
    cli("train-empty-hidden", "train {I}/data.npz --model cvae --set hidden=[] -o {O}/m", "hidden=[]"),
    cli("train-zero-width", "train {I}/data.npz --model cvae --set hidden=[0,4] -o {O}/m", "hidden=[0, 4]"),
    cli("train-too-large", "train {I}/data.npz --model cvae --set hidden=[100000,100000] -o {O}/m", "149.0 GiB"),
    cli("train-threads-huge", "train {I}/data.npz --threads 100000 -o {O}/m", "--threads must be from 1 to 256"),
    cli("plan-time-huge", "plan pose --scene wall -o {O}/p.npz --time 1e10", "--time must be from"),
    cli("sample-refine-huge", "sample {I}/model --condition 0.4 --refine 1000000 -o {O}/s.npz", "--refine must be from"),
    cli("bench-runs-huge", "bench plan pose --scene wall --runs 1000000000 -o {O}/b", "--runs must be from"),
    cli("train-text-latent", "train {I}/data.npz --model cvae --set latent=abc -o {O}/m", "abc"),
    cli("train-unknown-setting", "train {I}/data.npz --model cvae --set nope=1 -o {O}/m", "nope"),
    cli("train-set-no-equals", "train {I}/data.npz --model cvae --set noeq -o {O}/m", "noeq"),
    cli("train-zero-epochs", "train {I}/data.npz --epochs 0 -o {O}/m", "got 0"),
    cli("train-negative-seed", "train {I}/data.npz --seed -5 -o {O}/m", "-5"),
    cli("train-output-is-file", "train {I}/data.npz -o {I}/data.npz", "data.npz"),
    cli("train-output-parent-missing", "train {I}/data.npz -o {O}/no/where/m", "no/where"),
    cli("train-resume-nothing", "train {I}/data.npz --resume -o {O}/fresh", "fresh"),
    cli("train-missing-config", "train {I}/data.npz --model cvae --config {I}/none.toml -o {O}/m", "none.toml"),
    cli("train-bad-config", "train {I}/data.npz --model cvae --config {I}/bad.toml -o {O}/m", "bad.toml"),
    cli("train-single-condition", "train {I}/single.npz -o {O}/m", "[0.3]"),
    cli("train-reversed-joints", "train {I}/reversed.npz -o {O}/m", "panda_joint7"),
    cli("train-read-only", "train {I}/data.npz -o {O}/m", "Read-only file system", patch="read_only"),
    # sample
    cli("sample-zero", "sample {I}/model --condition 0.4 -n 0 -o {O}/s.npz", "got 0"),
    cli("sample-negative", "sample {I}/model --condition 0.4 -n -5 -o {O}/s.npz", "-5"),
    cli("sample-too-many", "sample {I}/model --condition 0.4 -n 100000000 -o {O}/s.npz", "100000000"),
    cli("sample-negative-refine", "sample {I}/model --condition 0.4 --refine -1 -o {O}/s.npz", "-1"),
    cli("sample-negative-seed", "sample {I}/model --condition 0.4 --seed -1 -o {O}/s.npz", "-1"),
    cli("sample-nan-condition", "sample {I}/model --condition nan -o {O}/s.npz", "nan"),
    cli("sample-strict-range", "sample {I}/model --condition 5 --strict -o {O}/s.npz", "5"),
    cli("sample-missing-model", "sample {I}/nomodel --condition 0.4 -o {O}/s.npz", "nomodel"),
    cli("sample-over-weights", "sample {I}/model --condition 0.4 -o {I}/model/model.safetensors", "model.safetensors"),
    cli("sample-over-config", "sample {I}/model --condition 0.4 -o {I}/model/model.json", "model.json"),
    cli("sample-output-is-dir", "sample {I}/model --condition 0.4 -o {O}", "is a folder"),
    cli("sample-edited-normalisation", "sample {I}/edited --condition 0.4 -o {O}/s.npz", "checksum"),
    cli("sample-widened-range", "sample {I}/widened --condition 0.8 --strict -o {O}/s.npz", "checksum"),
    cli("sample-version-1", "sample {I}/version1 --condition 0.4 -o {O}/s.npz", "format_version 1"),
    cli("sample-resigned-dims", "sample {I}/resigned --condition 0.4 -o {O}/s.npz", "must be 6"),
    cli("sample-truncated-weights", "sample {I}/cut --condition 0.4 -o {O}/s.npz", "model.safetensors"),
    cli("sample-unknown-task", "sample {I}/model --condition 0.4 --task poze -o {O}/s.npz", "poze"),
    cli("sample-disk-full", "sample {I}/model --condition 0.4 -n 5 -o {O}/s.npz", "No space left", patch="disk_full"),
    # plan
    cli("plan-unknown-scene", "plan pose --scene nowhere -o {O}/p.npz", "nowhere"),
    cli("plan-scene-not-utf8", "plan pose --scene {I}/latin1.json -o {O}/p.npz", "latin1.json"),
    cli("plan-malformed-mesh", "plan pose --scene {I}/mesh.json -o {O}/p.npz", "bad.stl"),
    cli("plan-missing-mesh", "plan pose --scene {I}/nomesh.json -o {O}/p.npz", "gone.stl"),
    cli("plan-obstacle-at-1e308", "plan pose --scene {I}/far.json -o {O}/p.npz", "1e+308"),
    cli("plan-huge-radius", "plan pose --scene {I}/huge.json -o {O}/p.npz", "1e+300"),
    cli("plan-resealed-hidden", "plan pose --scene wall --sampler cvae:{I}/rehidden -o {O}/p.npz",
        "gives config hidden = [9], but its 'decoder' weights have [8]: the file was edited"),
    cli("plan-too-many-obstacles", "plan pose --scene {I}/crowded.json -o {O}/p.npz",
        "the scene has 1,001 objects; at most 1,000 are supported"),
    cli("plan-condition-beyond-the-task", "plan pose --scene {I}/high.json -o {O}/p.npz",
        "the condition [0.95] lies outside the task's values (panda_hand_tcp.z in [0.2, 0.7] m): check the scene's"),
    cli("plan-negative-batch", "plan pose --scene wall --sampler project,batch=-5 -o {O}/p.npz", "batch=-5"),
    cli("plan-zero-batch", "plan pose --scene wall --sampler project,batch=0 -o {O}/p.npz", "batch=0"),
    cli("plan-project-refine", "plan pose --scene wall --sampler project,refine=2 -o {O}/p.npz", "refine"),
    cli("plan-bad-option", "plan pose --scene wall --sampler project,speed=2 -o {O}/p.npz", "speed=2"),
    cli("plan-over-pg-dataset", "plan pose --scene wall --sampler pg:{I}/data.npz -o {I}/data.npz", "data.npz"),
    cli("plan-over-scene", "plan pose --scene {I}/scene.json -o {I}/scene.json", "scene.json"),
    cli("plan-picture-over-path", "plan pose --scene wall -o {O}/p.png", "p.png"),
    cli("plan-snapshots-over-path", "plan pose --scene wall --snapshots {O}/p.npz -o {O}/p.npz", "p.npz"),
    cli("plan-picture-over-model", "plan pose --scene wall --sampler cvae:{I}/model -o {I}/model/loss.npz",
        "loss.png"),
    cli("plan-output-is-dir", "plan pose --scene wall -o {O}", "is a folder"),
    cli("plan-missing-model", "plan pose --scene wall --sampler cvae:{I}/nomodel -o {O}/p.npz", "nomodel"),
    cli("plan-edited-model", "plan pose --scene wall --sampler cvae:{I}/edited -o {O}/p.npz", "checksum"),
    cli("plan-wrong-model-kind", "plan pose --scene wall --sampler cgan:{I}/model -o {O}/p.npz", "cgan"),
    cli("plan-unknown-sampler", "plan pose --scene wall --sampler zzz -o {O}/p.npz", "zzz"),
    cli("plan-pg-text-file", "plan pose --scene wall --sampler pg:{I}/text.npz -o {O}/p.npz", "text.npz"),
    cli("plan-unknown-planner", "plan pose --scene wall --planner rrtx -o {O}/p.npz", "rrtx"),
    cli("plan-unknown-local", "plan pose --scene wall --local zigzag -o {O}/p.npz", "zigzag"),
    cli("plan-zero-time", "plan pose --scene wall --time 0 -o {O}/p.npz", "got 0"),
    cli("plan-nan-time", "plan pose --scene wall --time nan -o {O}/p.npz", "nan"),
    cli("plan-negative-range", "plan pose --scene wall --set range=-1 -o {O}/p.npz", "-1"),
    cli("plan-unknown-setting", "plan pose --scene wall --set nope=1 -o {O}/p.npz", "nope"),
    cli("plan-negative-seed", "plan pose --scene wall --seed -1 -o {O}/p.npz", "-1"),
    cli("plan-missing-config", "plan pose --scene wall --config {I}/none.toml -o {O}/p.npz", "none.toml"),
    # bench
    cli("bench-sampling-zero-samples", "bench sampling {I}/model --samples 0 -o {O}/b", "got 0"),
    cli("bench-sampling-zero-repeats", "bench sampling {I}/model --repeats 0 -o {O}/b", "--repeats"),
    cli("bench-sampling-huge-samples", "bench sampling {I}/model --samples 100000000 -o {O}/b", "100000000"),
    cli("collect-huge-rows", "collect pose --per-condition 100000000 -o {O}/x.npz", "100000000"),
    cli("bench-sampling-negative-refine", "bench sampling {I}/model --refine -1 -o {O}/b", "got -1"),
    cli("bench-sampling-zero-reference", "bench sampling {I}/model --reference 0 -o {O}/b", "--reference"),
    cli("bench-sampling-model-twice", "bench sampling {I}/model {I}/model -o {O}/b", "twice"),
    cli("bench-sampling-into-model", "bench sampling {I}/model -o {I}/model", "input folder"),
    cli("bench-sampling-missing-model", "bench sampling {I}/nomodel -o {O}/b", "nomodel"),
    cli("bench-sampling-output-is-file", "bench sampling {I}/model -o {I}/data.npz", "data.npz"),
    cli("bench-sampling-negative-seed", "bench sampling {I}/model --seed -1 -o {O}/b", "-1"),
    cli("bench-plan-zero-pg-rows", "bench plan pose --scene wall --pg-rows 0 -o {O}/b", "--pg-rows"),
    cli("bench-plan-zero-runs", "bench plan pose --scene wall --runs 0 -m rrtconnect@project -o {O}/b", "got 0"),
    cli("bench-plan-zero-workers", "bench plan pose --scene wall --workers 0 -m rrtconnect@project -o {O}/b",
        "and 0"),
    cli("bench-plan-negative-time", "bench plan pose --scene wall --time -1 -m rrtconnect@project -o {O}/b", "-1"),
    cli("bench-plan-unknown-planner", "bench plan pose --scene wall -m bogus -o {O}/b", "bogus"),
    cli("bench-plan-bad-ompl", "bench plan pose --scene wall -m ompl-foo-bar -o {O}/b", "ompl-foo-bar"),
    cli("bench-plan-negative-batch", "bench plan pose --scene wall -m rrtconnect@project,batch=-5 -o {O}/b",
        "batch=-5"),
    cli("bench-plan-unknown-baseline", "bench plan pose --scene wall -m rrtconnect@project --baseline nope -o {O}/b",
        "'nope'"),
    cli("bench-plan-output-is-file", "bench plan pose --scene wall -m rrtconnect@project -o {I}/data.npz",
        "data.npz"),
    cli("bench-plan-negative-seed", "bench plan pose --scene wall --seed -1 -o {O}/b", "-1"),
    cli("bench-plan-scene-not-utf8", "bench plan pose --scene {I}/latin1.json -o {O}/b", "latin1.json"),
    cli("bench-plan-into-model", "bench plan pose --scene wall -m rrtconnect@cvae:{I}/model -o {I}/model",
        "input folder"),
    cli("bench-maze-zero-runs", "bench maze --runs 0 -m rrtconnect@project -o {O}/b", "got 0"),
    cli("bench-wall-missing-model", "bench wall --model {I}/nomodel -o {O}/b", "nomodel"),
    # trajectory, view, robots, tasks, demo
    cli("trajectory-text-npz", "trajectory {I}/text.npz -o {O}/t.json", "text.npz"),
    cli("trajectory-bad-suffix", "trajectory {I}/path.npz -o {O}/t.txt", "t.txt"),
    cli("trajectory-zero-velocity", "trajectory {I}/path.npz --vel-scale 0 -o {O}/t.json", "0"),
    cli("view-snapshots-over-input", "view {I}/path.npz --snapshots {I}/path.npz", "path.npz"),
    cli("view-missing-file", "view {I}/none.npz --export {O}/v.html", "none.npz"),
    cli("robots-unknown", "robots ur99", "ur99"),
    cli("tasks-missing-file", "tasks {I}/none.toml", "none.toml"),
    cli("demo-unknown", "demo nope -o {O}/d", "nope"),
    cli("demo-output-is-file", "demo -o {I}/data.npz", "data.npz"),
    # the Python API
    api("api-dataset-text-npz", lambda I, O: Dataset.load(I / "text.npz"),
        "text.npz"),
    api("api-load-edited-model", lambda I, O: _model(I, "edited"), "checksum"),
    api("api-cvae-batch-zero", lambda I, O: CVAE(batch=0), "batch=0"),
    api("api-cvae-nan-beta", lambda I, O: CVAE(beta=float("nan")), "nan"),
    api("api-sample-nan", lambda I, O: _model(I).sample([float("nan")], 5), "nan"),
    api("api-collect-negative-seed", lambda I, O: _collect(I, O, seed=-1), "-1"),
    api("api-collect-zero-batch", lambda I, O: _collect(I, O, batch=0), "batch"),
    api("api-sample-to-file-zero", lambda I, O: _sample_to_file(I, O, count=0), "got 0"),
    api("api-sample-to-file-seed", lambda I, O: _sample_to_file(I, O, seed=2**40), str(2**40)),
    api("api-run-query-seed", lambda I, O: _plan(seed=-1), "-1"),
    api("api-parse-spec-batch", lambda I, O: parse_spec("cvae:m,batch=0"),
        "batch=0"),
    api("api-output-over-model", lambda I, O: check_output_path(I / "model" / "model.json", [I / "model"]),
        "model.json"),
    api("api-scene-not-utf8", lambda I, O: Scene.load(I / "latin1.json"),
        "latin1.json"),
    api("api-task-file-missing", lambda I, O: load_task_file(I / "no.toml"),
        "no.toml"),
    api("api-bench-sampling-samples", lambda I, O: run_sampling_bench([I / "model"], O / "b", samples=0,
                                                                     progress=False), "--samples"),
    api("api-atomic-disk-full", lambda I, O: atomic_write_text(O / "t.txt", "x"),
        "No space left", patch="disk_full"),
]


def _read_only(monkeypatch):
    def refuse(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")
    monkeypatch.setattr("manifoldgen.io.tempfile.mkstemp", refuse)


def _disk_full(monkeypatch):
    class Full(io.FileIO):
        def write(self, data):
            raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr("manifoldgen.io.os.fdopen", lambda fd, mode="wb": Full(fd, "wb"))


PATCHES = {"read_only": _read_only, "disk_full": _disk_full}


def test_the_table_is_large_enough():
    assert len(CASES) >= 80 and len({c.id for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input(case, inputs, tmp_path, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    if case.patch:
        PATCHES[case.patch](monkeypatch)
    message = refused_cleanly(case, inputs, out)
    assert case.needle in message, message
    leftovers = [p.name for p in out.rglob("*") if p.name.endswith((".tmp", ".partial"))]
    assert not leftovers, leftovers
