"""Refusals of the fifth hostile round through the command line: a bench whose methods fail after it wrote its
files, a bench folder's runs.jsonl that is a link, an unreadable model.json for --model, a --seen condition no model
was trained at, a setting or sampler option given twice, --smooth with shortcut=0, sweep --epochs out of range and an
edited sweep.json row, a tiny --acc-scale, a file where the demo writes its model folder, a path given to the
project sampler; each one line naming the problem and the fix, nothing written, no input changed."""

from __future__ import annotations

import json
import os
import shutil

import pytest
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.ompl_settings import OmplSettings
from manifoldgen.tasks import get_task
from refusals import cli, refused_as_told

runner = CliRunner()
BENCH = "bench plan pose --scene wall --runs 1 --time 2"


def _ok(*args) -> None:
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, planned_path):
    """A dataset and a tiny model of it, a sweep and a copy with a forged row, a path file, model folders with an
    unreadable model.json, a bench folder whose runs.jsonl links to a user's file, a demo folder holding a file
    named model."""
    from manifoldgen.data import collect
    from manifoldgen.models import CVAE

    root = tmp_path_factory.mktemp("inputs")
    data = collect(get_task("pose", "panda"), 12, seed=0, conditions=[[0.3], [0.5]], progress=False)
    data.save(root / "data.npz")
    CVAE(hidden=[8], batch=8, epochs=1, patience=5).fit(data, seed=0, progress=False, out=root / "model")
    shutil.copy(planned_path("wall"), root / "path.npz")
    for name, doc in (("bm-empty", "{}"), ("bm-list", "[]")):
        (root / name).mkdir()
        (root / name / "model.json").write_text(doc)
    shutil.copy(root / "model" / "model.safetensors", root / "bm-list")
    _ok("sweep", root / "data.npz", "--model", "cvae", "--epochs", 1, "-o", root / "sweep")
    shutil.copytree(root / "sweep", root / "sweep-forged")
    doc = json.loads((root / "sweep-forged" / "sweep.json").read_text())
    doc["candidates"].append({**doc["candidates"][0], "name": "../../foreign/m", "accuracy": 1.0, "recall": 1.0})
    (root / "sweep-forged" / "sweep.json").write_text(json.dumps(doc))
    (root / "linked").mkdir()
    (root / "log.txt").write_text("my log line\n")
    os.symlink(root / "log.txt", root / "linked" / "runs.jsonl")
    (root / "demo").mkdir()
    (root / "demo" / "model").write_text("my model notes")
    return root


CASES = [
    # bench checks every method's sampler and OMPL settings, and its folder, before it writes anything
    cli("bench-missing-model-after-files", BENCH + " -m rrtconnect@cvae:{O}/nonexist -o {O}/b",
        "no trained model at '{O}/nonexist'"),
    cli("bench-ompl-setting-after-files", BENCH + " -m ompl-atlas-rrtconnect --set ompl_range=-1 -o {O}/b",
        "invalid OMPL settings: ompl_range is -1.0; need ompl_range >= 0"),
    cli("bench-project-refine-after-files", BENCH + " -m rrtconnect@project,refine=3 -o {O}/b",
        "the project sampler takes no refine option"),
    cli("bench-sampling-refusal-leaves-folder", "bench sampling {I}/model --unseen 0.3 -o {O}/b",
        "--unseen [0.3] is a condition a model was trained at"),
    cli("bench-sampling-seen-not-trained", "bench sampling {I}/model --seen 0.75 --unseen 0.25 -o {O}/b",
        "--seen [0.75] is not a condition model {I}/model was trained at (it was at [0.3, 0.5])"),
    cli("bench-runs-jsonl-symlink", BENCH + " -m rrtconnect@project -o {I}/linked",
        "{I}/linked/runs.jsonl is a symbolic link; bench writes its own runs.jsonl in the folder, never through a "
        "link"),
    cli("bench-model-json-empty", BENCH + " --model {I}/bm-empty -o {O}/b", "{I}/bm-empty is missing model.safetensors"),
    cli("bench-maze-model-json-list", "bench maze --runs 1 --time 2 --model {I}/bm-list -o {O}/b",
        "{I}/bm-list/model.json: not a JSON object"),
    # a setting or a sampler option given twice
    cli("train-set-twice", "train {I}/data.npz --model cvae --epochs 1 --set hidden=[8] --set hidden=[16] -o {O}/b",
        "--set hidden is given twice (which one counts is ambiguous); give each setting once"),
    cli("bench-set-twice", BENCH + " -m rrtconnect@project --set range=0.5 --set range=0.9 -o {O}/b",
        "--set range is given twice"),
    cli("plan-sampler-option-twice", "plan pose --scene wall --no-picture --sampler cvae:{I}/model,refine=2,refine=9 "
        "-o {O}/p.npz", "sampler option refine is given twice in 'cvae:{I}/model,refine=2,refine=9'"),
    cli("plan-smooth-with-shortcut-zero", "plan pose --scene wall --no-picture --smooth --set shortcut=0 -o {O}/p.npz",
        "--smooth asks for shortcut attempts, but shortcut=0 (from --set or --config) allows none"),
    cli("plan-project-with-a-path", "plan pose --scene wall --no-picture --sampler project:foo -o {O}/p.npz",
        "the project sampler takes no path (got 'project:foo'); give project alone, or MODEL:DIR"),
    # sweep: train's --epochs range; a row of sweep.json that no candidate of its settings makes
    cli("sweep-epochs-above-range", "sweep {I}/data.npz --model cvae --epochs 100001 -o {O}/b",
        "--epochs must be from 1 to 100000, got 100001"),
    cli("sweep-forged-row-installs-foreign-model", "sweep {I}/data.npz --model cvae --epochs 1 -o {I}/sweep-forged",
        "sweep.json holds a row named \"../../foreign/m\", not a candidate of its settings"),
    cli("trajectory-acc-scale-tiny", "trajectory {I}/path.npz --acc-scale 1e-9 -o {O}/b.json",
        "--acc-scale must be in (0, 1], at least 0.001"),
    cli("trajectory-vel-scale-tiny", "trajectory {I}/path.npz --vel-scale 1e-4 -o {O}/b.json",
        "--vel-scale must be in (0, 1], at least 0.001"),
    cli("demo-model-is-a-file", "demo -o {I}/demo",
        "-o {I}/demo holds a file model where the pose demo writes its folder; move or delete it"),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_refused_in_one_line_with_nothing_written(case, inputs, tmp_path):
    refused_as_told(case, inputs, tmp_path)


def test_the_linked_users_file_is_untouched(inputs):
    assert (inputs / "log.txt").read_text() == "my log line\n"


def test_a_normal_bench_with_a_collected_pg_dataset_runs_and_resumes(tmp_path):
    out = tmp_path / "b"
    args = [*BENCH.split(), "-m", "rrtconnect@project", "-m", "rrtconnect@pg", "--pg-rows", "200",
            "--set", "range=0.8", "--set", "shortcut=5", "-o", out]
    _ok(*args)
    _ok(*args[:-2], "--runs", "2", "--resume", "-o", out)  # --runs 2 after --runs 1: the last one counts
    runs = [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines()]
    assert sorted((r["method"], r["run"]) for r in runs) == [("rrtconnect@pg", 0), ("rrtconnect@pg", 1),
                                                               ("rrtconnect@project", 0), ("rrtconnect@project", 1)]


def test_a_trained_seen_condition_smoothing_and_good_ompl_settings_pass(inputs, tmp_path):
    _ok("bench", "sampling", inputs / "model", "--seen", "0.3", "--unseen", "0.25", "--samples", 100, "--reference",
        100, "--repeats", 1, "-o", tmp_path / "bs")
    _ok("plan", "pose", "--scene", "wall", "--time", 10, "--no-picture", "--smooth", "--set", "shortcut=5",
        "--sampler", f"cvae:{inputs / 'model'},refine=2,batch=64", "-o", tmp_path / "p.npz")
    _ok("trajectory", tmp_path / "p.npz", "--acc-scale", "0.001", "--vel-scale", "0.5", "-o", tmp_path / "t.json")
    assert OmplSettings.from_benchmark({"ompl_range": 0.45, "ompl_epsilon": 0.1, "shortcut": 5}).range == 0.45


def test_a_sweep_resumes(inputs, tmp_path):
    shutil.copytree(inputs / "sweep", tmp_path / "s")
    before = (tmp_path / "s" / "model.safetensors").read_bytes()
    _ok("sweep", inputs / "data.npz", "--model", "cvae", "--epochs", 1, "-o", tmp_path / "s")
    assert (tmp_path / "s" / "model.safetensors").read_bytes() == before
