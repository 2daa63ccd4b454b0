"""The command line against hostile input: outputs of the wrong kind or in a folder that takes no file, an SRDF of
another robot, empty names, values that are not numbers, a model folder with a comma, a bench resume with other
arguments. A refusal is exit code 2 and one `error:` line on stderr naming the problem and the fix, nothing
written and no input changed."""

from __future__ import annotations

import json
import shutil

import pytest
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.data import collect
from manifoldgen.io import load_npz, save_npz
from manifoldgen.models import CVAE
from manifoldgen.robot import resolve_robot, robots_dir
from manifoldgen.robot.catalogue import file_sha256
from manifoldgen.specs import parse_spec
from manifoldgen.tasks import BUILTIN_DIR
from refusals import cli, refused_cleanly

runner = CliRunner()
UR5_SRDF = robots_dir() / "ur_description" / "srdf" / "ur5.srdf"
PANDA_SHA = file_sha256(resolve_robot("panda")[0])[:12]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, panda_task, planned_path):
    """Small input files, made once: dataset (and one with a wrong URDF hash), model (and a copy in a folder whose
    name holds a comma), path, scene, task files (one naming the ur5's SRDF) and an unrelated .npz."""
    root = tmp_path_factory.mktemp("inputs")
    data = collect(panda_task, 12, seed=0, conditions=[[0.3], [0.5]], progress=False)
    data.save(root / "data.npz")
    meta, arrays = load_npz(root / "data.npz", ())
    meta["task"]["robot"]["urdf_sha256"] = "0" * 64
    save_npz(root / "badsha.npz", meta, **arrays)
    CVAE(hidden=[8], batch=8, epochs=1, patience=5).fit(data, seed=0, progress=False, out=root / "model")
    shutil.copytree(root / "model", root / "m,1")
    shutil.copy(planned_path("wall"), root / "path.npz")
    shutil.copy(root / "data.npz", root / "keep.npz")
    shutil.copy(BUILTIN_DIR / "scenes" / "panda-wall.json", root / "scene.json")
    text = (BUILTIN_DIR / "pose-panda.toml").read_text().replace('"scenes/', f'"{BUILTIN_DIR}/scenes/')
    (root / "task.toml").write_text(text)
    (root / "ur5srdf.toml").write_text(text.replace('robot = "panda"', f'robot = "panda"\nsrdf = "{UR5_SRDF}"'))
    return root


CASES = [
    # an output folder that takes no file is refused before the work, the outputs before it left alone
    cli("plan-snapshots-unwritable", "plan pose --scene wall --time 5 --snapshots /sys/x.png -o {O}/s.npz",
        "cannot write /sys/x.png: Permission denied"),
    cli("collect-unwritable", "collect pose --per-condition 5 -o /sys/x.npz", "cannot write /sys/x.npz"),
    # every file output ends in its kind's suffix: an unrelated file is never replaced by another kind
    cli("view-export-over-npz", "view {I}/path.npz --export {I}/keep.npz",
        "--export must end in .html, got {I}/keep.npz; give a name such as keep.html"),
    cli("view-snapshots-jpg", "view {I}/path.npz --snapshots {O}/s.jpg", "--snapshots must end in .png, got {O}/s.jpg"),
    cli("physics-over-npz", "physics {I}/path.npz -o {I}/keep.npz", "-o must end in .json, got {I}/keep.npz"),
    cli("plan-over-scene-json", "plan pose --scene wall --time 5 -o {I}/scene.json",
        "-o must end in .npz, got {I}/scene.json"),
    cli("plan-snapshots-jpg", "plan pose --scene wall --snapshots {O}/s.jpg -o {O}/p.npz",
        "--snapshots must end in .png, got {O}/s.jpg"),
    cli("plan-roadmap-dat", "plan pose --scene wall --roadmap {O}/r.dat -o {O}/p.npz",
        "--roadmap must end in .npz, got {O}/r.dat"),
    cli("collect-over-toml", "collect pose --per-condition 5 --condition 0.3 -o {I}/task.toml",
        "-o must end in .npz, got {I}/task.toml"),
    cli("sample-over-json", "sample {I}/model --condition 0.4 -n 5 -o {O}/s.json",
        "-o must end in .npz, got {O}/s.json"),
    cli("trajectory-txt", "trajectory {I}/path.npz -o {O}/t.txt", "-o must end in .json or .csv, got {O}/t.txt"),
    # an SRDF of another robot
    cli("robots-foreign-srdf", f"robots panda --srdf {UR5_SRDF}",
        "is not for robot panda: 7 of the 7 links and joints it names are not panda's (base_link, shoulder_link"),
    cli("task-file-foreign-srdf", "collect {I}/ur5srdf.toml --per-condition 5 -o {O}/x.npz",
        "is not for robot panda"),
    cli("robots-srdf-alone", f"robots --srdf {UR5_SRDF}", "--srdf goes with a robot"),
    # --robot without --task, an empty robot name
    cli("sample-robot-without-task", "sample {I}/model --condition 0.4 --robot pr2 -n 5 -o {O}/s.npz",
        "--robot picks the robot of a built-in --task; give --task too"),
    cli("collect-empty-robot", ["collect", "pose", "--robot", "", "-o", "{O}/x.npz"], "--robot is empty"),
    cli("plan-empty-robot", ["plan", "pose", "--robot", " ", "--scene", "wall", "-o", "{O}/p.npz"],
        "--robot is empty"),
    cli("sample-empty-robot", ["sample", "{I}/model", "--condition", "0.4", "--task", "pose", "--robot", "",
                               "-o", "{O}/s.npz"], "--robot is empty"),
    cli("bench-empty-robot", ["bench", "plan", "pose", "--scene", "wall", "--robot", "", "-m", "rrtconnect",
                              "-o", "{O}/b"], "--robot is empty"),
    cli("robots-empty", ["robots", ""], "the robot name is empty; give a robot name (`manifoldgen robots` lists"),
    cli("robots-unknown-short", "robots pandaa", "unknown robot 'pandaa' (did you mean panda?); give one of the"),
    # a URDF hash no file has: said once, with something to do
    cli("train-wrong-urdf-hash", "train {I}/badsha.npz --model cvae --epochs 1 -o {O}/m",
        f"(robot 'panda'): panda has {PANDA_SHA}; pass the path of the URDF the file was made with (on the command "
        "line: --task FILE"),
    # a sampler option that is not one, beside a path that does not exist
    cli("plan-comma-path-missing", "plan pose --scene wall --sampler cvae:{I}/nothere,1 -o {O}/p.npz",
        "bad sampler option '1'"),
    # usage errors: one line
    cli("sample-empty-condition", ["sample", "{I}/model", "--condition", "", "-o", "{O}/s.npz"],
        "invalid value for '--condition': '' is not a valid float; see `"),
    cli("sample-n-not-a-number", "sample {I}/model --condition 0.4 -n abc -o {O}/s.npz",
        "invalid value for '-n': 'abc' is not a valid int; see `"),
    cli("collect-unknown-option", "collect pose --bogus -o {O}/x.npz", "no such option: --bogus"),
    cli("plan-missing-scene", "plan pose -o {O}/p.npz", "missing option '--scene'"),
    cli("bench-missing-task", "bench plan --scene wall -o {O}/b", "missing argument 'task'"),
    cli("unknown-command", "plann pose", "no such command 'plann'"),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_refused_in_one_line_on_stderr(case, inputs, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    message = refused_cleanly(case, inputs, out)
    assert case.needle.format(I=inputs, O=out) in message, message
    assert len(message.replace(str(inputs), "I").replace(str(out), "O")) < 300, message
    assert not list(out.rglob("*")), "a refused command wrote files"


def test_a_model_folder_with_a_comma_is_read_whole(inputs, tmp_path):
    folder = str(inputs / "m,1")
    assert parse_spec(f"cvae:{folder}") == ("cvae", folder, {})
    assert parse_spec(f"cvae:{folder},refine=2") == ("cvae", folder, {"refine": 2})
    assert parse_spec("project,batch=5") == ("project", "", {"batch": 5})
    result = runner.invoke(app, ["plan", "pose", "--scene", "wall", "--time", "10", "--no-picture", "--sampler",
                                 f"cvae:{folder},refine=2", "-o", str(tmp_path / "p.npz")])
    assert result.exit_code == 0 and (tmp_path / "p.npz").is_file(), result.output


def test_the_robots_own_srdf_is_accepted():
    srdf = robots_dir() / "panda_description" / "srdf" / "panda.srdf"
    result = runner.invoke(app, ["robots", "panda", "--srdf", str(srdf)])
    assert result.exit_code == 0 and f"SRDF {srdf}" in result.output, result.output


def test_a_sweep_warns_of_a_small_latent_with_its_own_option(inputs, tmp_path):
    result = runner.invoke(app, ["sweep", str(inputs / "data.npz"), "--model", "cvae", "--latent", "2", "--latent",
                                 "4", "--epochs", "1", "-o", str(tmp_path / "sweep")], terminal_width=400)
    assert result.exit_code == 0, result.output
    warned = [line for line in result.stderr.splitlines() if line.startswith("warning: ")]
    assert warned == ["warning: --latent 2 is below the constraint manifold's dimension 3 (joints minus the "
                      "constraint Jacobian's rank): those candidates' samples cover at most a sheet of it; sweep "
                      "with --latent 3 (or more)"], result.output


def test_a_bench_resume_adds_methods_and_refuses_other_settings(tmp_path):
    out = tmp_path / "b"

    def bench(*args):
        return runner.invoke(app, ["bench", "plan", "pose", "--scene", "wall", "--runs", "1", "-o", str(out),
                                   *args], terminal_width=400)

    assert bench("-m", "p=rrtconnect@project", "--time", "2").exit_code == 0
    added = bench("-m", "u=rrtconnect@project,batch=64", "--time", "2", "--resume")
    assert added.exit_code == 0, added.output
    config = json.loads((out / "config.json").read_text())
    assert config["methods"] == ["p=rrtconnect@project", "u=rrtconnect@project,batch=64"]
    assert "runs.jsonl also holds runs of `p`, not in this table" in (out / "results.md").read_text()
    runs = (out / "runs.jsonl").read_bytes()
    for args, needle in ((["-m", "p=rrtconnect@project", "--time", "3"], "other settings: time_limit 2.0, not 3.0"),
                         (["-m", "p=rrtconnect@uniform", "--time", "2"],
                          "holds method 'p' as 'p=rrtconnect@project', not 'p=rrtconnect@uniform'")):
        refused = bench(*args, "--resume")
        assert refused.exit_code == 2 and needle in refused.stderr, refused.output
    assert (out / "runs.jsonl").read_bytes() == runs
