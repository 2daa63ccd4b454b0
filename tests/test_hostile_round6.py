"""Refusals and fixes of the sixth hostile round: a .json output of another kind (a trajectory over a physics report
and back), a dataset given as a task file, a task file's missing scene, tolerances given as text or true, a path
stored as float32, a method label holding a newline, torch threads out of range through the API, and from its
held-out share: a dataset with no rows to view, a home outside the joint limits, a user's module exiting, a bench
config.json that no longer lists the methods of its runs, a model directory that is a link loop, a folder given as a
pg dataset, sampling conditions of the wrong width; each one line naming the problem, nothing written, no input
changed. Accepted: a task file with a UTF-8 byte-order mark, an
output name the terminal cannot encode. The outside checker does not vouch for a bench folder with no solved run."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.models import CVAE
from manifoldgen.tasks import BUILTIN_DIR
from refusals import api, cli, edited_npz, refused_as_told

runner = CliRunner()
ROOT = Path(__file__).resolve().parents[1]
USER = ROOT / "examples" / "user_task"
PANDA = (BUILTIN_DIR / "pose-panda.toml").read_text().replace('"scenes/', f'"{BUILTIN_DIR}/scenes/')


def _ok(*args) -> None:
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, planned_path):
    """A path file and its float32 copy, a physics report and two trajectories (with and without their kind),
    task files (a missing scene, text and boolean tolerances, a byte-order mark) and a dataset."""
    from manifoldgen.data import collect
    from manifoldgen.tasks import get_task

    root = tmp_path_factory.mktemp("inputs")
    path = root / "path.npz"
    path.write_bytes(planned_path("wall").read_bytes())
    edited_npz(path, root / "p32.npz", arrays=lambda a: a.update(path=a["path"].astype(np.float32)))
    (root / "report.json").write_text(json.dumps({"generator": "manifoldgen", "kind": "physics", "upright": True}))
    _ok("trajectory", path, "-o", root / "traj.json")
    doc = json.loads((root / "traj.json").read_text())
    assert doc["kind"] == "trajectory"
    doc.pop("kind")  # as written before files carried a kind: told by its points and joint names
    (root / "old-traj.json").write_text(json.dumps(doc))
    (root / "scene-missing.toml").write_text(PANDA.replace('[scenes]\n', '[scenes]\ngone = "nope.json"\n'))
    tables = PANDA.replace('position_axes = ["z"]\n', 'position_axes = ["z"]\nTOL\n')
    (root / "tol-str.toml").write_text(tables.replace("TOL", 'orientation_tolerance = "0.01"'))
    (root / "tol-bool.toml").write_text(tables.replace("TOL", "position_tolerance = true"))
    (root / "bom.toml").write_bytes(b"\xef\xbb\xbf" + PANDA.encode())
    data = collect(get_task("pose", "panda"), 6, seed=0, conditions=[[0.3], [0.5]], progress=False)
    data.save(root / "data.npz")
    edited_npz(root / "data.npz", root / "no-rows.npz", arrays=lambda a: a.update(q=a["q"][:0], y=a["y"][:0]))
    (root / "home-huge.toml").write_text(PANDA.replace("home = [0.0,", "home = [1e300,"))
    user = root / "user"
    user.mkdir()
    shutil.copy(USER / "tool_down.py", user / "tool_down.py")
    (user / "exits.py").write_text("from tool_down import ToolDownAtX\nclass C(ToolDownAtX):\n"
                                   "    def __init__(self, *a, **k):\n        raise SystemExit(0)\n")
    (user / "task.toml").write_text((USER / "tool-down-xarm7.toml").read_text().replace(
        "tool_down:ToolDownAtX", "exits:C").replace('open = "open.json"', f'open = "{USER / "open.json"}"'))
    _ok("bench", "plan", "pose", "--scene", "wall", "--runs", 1, "--time", 2, "-m", "rrtconnect@project",
        "-o", root / "bench")
    config = json.loads((root / "bench" / "config.json").read_text())
    config["methods"] = ["rrtconnect@cvae:elsewhere"]  # no longer lists the method its runs were made with
    (root / "bench" / "config.json").write_text(json.dumps(config))
    CVAE(hidden=[8], batch=8, epochs=1, patience=5).fit(data, seed=0, progress=False, out=root / "model")
    os.symlink(root / "loop", root / "loop")
    return root


CASES = [
    cli("trajectory-over-physics-report", "trajectory {I}/path.npz -o {I}/report.json",
        "-o {I}/report.json holds a physics file, which this trajectory file would replace"),
    cli("physics-over-trajectory", "physics {I}/path.npz -o {I}/traj.json",
        "-o {I}/traj.json holds a trajectory file, which this physics file would replace"),
    cli("physics-over-older-trajectory", "physics {I}/path.npz -o {I}/old-traj.json",
        "holds a trajectory file, which this physics file would replace"),
    cli("collect-task-is-a-dataset", "collect {I}/data.npz -o {O}/d.npz",
        "{I}/data.npz is a zip archive (an .npz dataset, path or roadmap?), not a task file (TOML text)"),
    cli("tasks-scene-missing", "tasks {I}/scene-missing.toml",
        "scene 'gone': {I}/nope.json does not exist (scene paths are relative to the task file's folder)"),
    cli("tasks-tolerance-text", "tasks {I}/tol-str.toml",
        "orientation_tolerance must be a finite number (written without quotes), got '0.01'"),
    cli("tasks-tolerance-true", "tasks {I}/tol-bool.toml", "position_tolerance must be a finite number, got True"),
    cli("view-path-float32", "view {I}/p32.npz --export {O}/v.html",
        "'path' must be a non-empty (K, n) float64 array of finite numbers (as `plan` writes it), got float32"),
    cli("bench-label-newline", ["bench", "plan", "pose", "--scene", "wall", "--runs", "1", "--time", "2", "-m",
                                "a\nb=rrtconnect@project", "-o", "{O}/b"],
        "label 'a\\nb' is not a plain name"),
    cli("view-dataset-no-rows", "view {I}/no-rows.npz --export {O}/v.html",
        "{I}/no-rows.npz holds no rows: nothing to show"),
    cli("tasks-home-outside-limits", "tasks {I}/home-huge.toml",
        "home panda_joint1 = 1e+300 is outside its limits [-2.8973, 2.8973]; give a home inside the joint limits"),
    api("load-task-user-code-exits", lambda I, O: __import__("manifoldgen").load_task(I / "user" / "task.toml"),
        "exits.py, line 4 called exit(0) while its task was read; a constraint's module must not exit"),
    cli("bench-resume-config-without-its-runs", "bench plan pose --scene wall --runs 2 --time 2 -m rrtconnect@project "
        "--resume -o {I}/bench", "{I}/bench/config.json does not list method 'rrtconnect@project' as "
        "'rrtconnect@project', which runs.jsonl holds runs of: the folder was edited"),
    cli("sample-model-link-loop", "sample {I}/loop --condition 0.4 -o {O}/s.npz",
        "model directory {I}/loop is a symbolic link loop"),
    cli("plan-pg-of-a-folder", "plan pose --scene wall --no-picture --sampler pg:{I}/model -o {O}/p.npz",
        "dataset {I}/model is a directory, not a file; give the dataset's .npz"),
    api("sample-y-of-another-width", lambda I, O: __import__("manifoldgen").load_model(I / "model").sample(
        np.zeros((2, 3)), 2), "y must hold conditions of 1 value(s) each, as (k,), (1, k) or (n, k) with k = 1; got "
        "shape (2, 3)"),
    api("set-threads-million", lambda I, O: __import__("manifoldgen.runtime").runtime.set_threads(10**6),
        "threads must be a whole number from 1 to 256, got 1000000"),
    api("set-threads-text", lambda I, O: __import__("manifoldgen.runtime").runtime.set_threads("2"),
        "threads must be a whole number from 1 to 256, got '2'"),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_refused_in_one_line_with_nothing_written(case, inputs, tmp_path):
    refused_as_told(case, inputs, tmp_path)


def test_a_task_file_with_a_byte_order_mark_reads_as_without(inputs):
    result = runner.invoke(app, ["tasks", str(inputs / "bom.toml")])
    assert result.exit_code == 0 and "panda_hand_tcp.z in [0.2, 0.7] m" in result.output, result.output


def test_a_name_the_terminal_cannot_encode_is_printed_escaped(tmp_path):
    env = {**os.environ, "PYTHONIOENCODING": "ascii", "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-c", "from manifoldgen.cli import app; app()", "collect", "pose",
                           "--per-condition", "5", "--no-anchors", "-o", "données.npz"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    assert "wrote donn\\xe9es.npz" in done.stdout and (tmp_path / "données.npz").is_file()


def test_the_checker_does_not_vouch_for_a_bench_with_no_solved_run(tmp_path):
    _ok("bench", "plan", "pose", "--scene", "wall", "--runs", 1, "--time", 2, "-m", "rrtconnect@project",
        "-o", tmp_path / "b")
    (tmp_path / "b" / "runs.jsonl").write_text("")
    done = subprocess.run([sys.executable, str(ROOT / "examples" / "check_path.py"), str(tmp_path / "b")],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 3, done.stdout + done.stderr
    assert "CANNOT RECHECK: no solved run to recheck (0 runs in runs.jsonl, none solved)" in done.stdout


def test_a_sigterm_is_never_blamed_on_user_code(tmp_path):
    """A SIGTERM stops a command with exit 143 wherever it lands: in a user's module (the signal is not its fault)
    or in a compiled extension's frame (numpy's ``numpy/random/_generator.pyx``, a file that does not exist here,
    once taken for a user's module: exit 2, "user code ... raised SystemExit")."""
    (tmp_path / "busy.py").write_text("import os, signal\n\ndef run():\n    os.kill(os.getpid(), signal.SIGTERM)\n"
                                      "    while True:\n        pass\n")
    script = ("import sys\nfrom manifoldgen.cli_common import friendly\nimport busy\n"
              "try:\n    friendly(busy.run)()\nexcept SystemExit as exc:\n    sys.exit(exc.code)\n")
    done = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": str(tmp_path)})
    assert done.returncode == 128 + signal.SIGTERM and "user code" not in done.stderr, done.stderr
    from manifoldgen.errors import user_code
    try:
        exec(compile("raise SystemExit(143)", "numpy/random/_generator.pyx", "exec"), {})
    except SystemExit as exc:
        assert user_code(exc.with_traceback(exc.__traceback__.tb_next)) is None  # its frame alone, not this test's


def test_sigterm_stops_a_writer_as_ctrl_c_does_its_lock_released(tmp_path):
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    job = subprocess.Popen([sys.executable, "-c", "from manifoldgen.cli import app; app()", "collect", "pose",
                            "--per-condition", "100000", "-o", "a.npz"], cwd=tmp_path, env=env,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for _ in range(600):  # until its first batch is kept for a resume
        if list((tmp_path / "a.npz.partial").glob("*.npz")) or job.poll() is not None:
            break
        time.sleep(0.1)
    job.send_signal(signal.SIGTERM)
    assert job.wait(timeout=60) == 128 + signal.SIGTERM
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.npz.partial"]  # kept for a resume; the lock is gone
