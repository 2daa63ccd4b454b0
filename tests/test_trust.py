"""Files are data, never code: a dataset, model or path file naming a user's ``module:Class`` constraint is
refused (one line) without importing anything or touching ``sys.path``; its recorded ``task_file`` is
information only. Also: one writer per output (lock files), labels that become file names are plain names,
and the viewer's websocket accepts only its own page's Origin."""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import viser
from typer.testing import CliRunner
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from manifoldgen.bench.planning import Method
from manifoldgen.cli import app
from manifoldgen.data import collect
from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import load_npz, output_lock, save_npz
from manifoldgen.models import pretrained_model_dir
from manifoldgen.models.base import document_checksum
from manifoldgen.tasks import task_from_meta
from manifoldgen.viewer.server import ORIGIN_REFUSED, free_port, origin_allowed, start_server, stop_server

runner = CliRunner()
SRC = Path(__file__).resolve().parents[1] / "src"
PLANTED = ("evil", "matplotlib", "toppra", "viser", "probe")  # modules a hostile folder plants


def _one_error(result) -> str:
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and "Traceback" not in result.output, result.output
    return errors[0]


@pytest.fixture(scope="module")
def hostile(tmp_path_factory, panda_task, planned_path):
    """A folder of modules that leave a marker file when imported, and panda pose files (dataset, model, path)
    whose meta points ``task_file`` there: ``user/`` ones name the type ``evil:Thing``, ``this/`` ones the
    standard library's ``this:X``, ``builtin/`` ones keep their built-in constraint."""
    root = tmp_path_factory.mktemp("hostile")
    planted = root / "planted"
    planted.mkdir()
    for name in PLANTED:
        marker = str(planted / f"{name}-ran")
        (planted / f"{name}.py").write_text(f"open({marker!r}, 'w').close()\nclass Thing: pass\n")
    data = collect(panda_task, 12, seed=0, conditions=[[0.3], [0.5]], progress=False)
    for kind, ctype in (("user", "evil:Thing"), ("this", "this:X"), ("builtin", None)):
        folder = root / kind
        folder.mkdir()

        def edit(meta: dict) -> dict:
            meta = json.loads(json.dumps(meta))
            meta["task"]["task_file"] = str(planted / "task.toml")
            if ctype is not None:
                meta["task"]["constraint"]["type"] = meta["constraint"]["type"] = ctype
            return meta
        save_npz(folder / "d.npz", edit(data.meta), q=data.q, y=data.y)
        meta, arrays = load_npz(planned_path("wall"), ("path",))
        save_npz(folder / "p.npz", edit(meta), **arrays)
        shutil.copytree(pretrained_model_dir(), folder / "m")
        doc = json.loads((folder / "m" / "model.json").read_text())
        doc["meta"] = edit(doc["meta"])
        doc["sha256"] = document_checksum(doc)  # a checksum, not a signature: anyone can recompute it
        (folder / "m" / "model.json").write_text(json.dumps(doc))
    return root


@pytest.fixture
def untouched(hostile):
    """Asserts, after the test, that nothing planted ran, no planted module is importable and sys.path is as
    it was."""
    before = list(sys.path)
    yield
    assert sys.path == before
    assert not [p.name for p in (hostile / "planted").glob("*-ran")]
    assert importlib.util.find_spec("probe") is None and "evil" not in sys.modules and "this" not in sys.modules


REFUSED = [
    ("train", "train {H}/user/d.npz -o {O}/m"),
    ("sample", "sample {H}/user/m --condition 0.4 -o {O}/s.npz"),
    ("view-export-path", "view {H}/user/p.npz --export {O}/v.html"),
    ("view-export-dataset", "view {H}/user/d.npz --export {O}/v.html"),
    ("view-snapshots", "view {H}/user/p.npz --snapshots {O}/v.png"),
    ("trajectory", "trajectory {H}/user/p.npz -o {O}/t.json"),
    ("bench-sampling", "bench sampling {H}/user/m -o {O}/b"),
    ("this-module", "trajectory {H}/this/p.npz -o {O}/t.json"),
]


@pytest.mark.parametrize("args", [a for _, a in REFUSED], ids=[i for i, _ in REFUSED])
def test_a_file_naming_user_code_is_refused_and_nothing_is_imported(args, hostile, untouched, tmp_path):
    message = _one_error(runner.invoke(app, args.format(H=hostile, O=tmp_path).split()))
    assert ("evil:Thing" in message or "this:X" in message) and "--task FILE" in message and "--trust-code" in message
    assert not list(tmp_path.iterdir()), "nothing is written"


def test_the_api_refuses_too(hostile, untouched):
    for kind in ("user", "this"):
        meta, _ = load_npz(hostile / kind / "d.npz", ("q",))
        with pytest.raises(ManifoldgenError, match="reading a file never imports code"):
            task_from_meta(meta)


def test_a_recorded_task_file_is_information_only(hostile, untouched, tmp_path):
    """Built-in constraint types work from files alone; their task_file (the planted folder) is never on sys.path."""
    for args in (f"trajectory {hostile}/builtin/p.npz -o {tmp_path}/t.json",
                 f"sample {hostile}/builtin/m --condition 0.4 -n 20 -o {tmp_path}/s.npz",
                 f"train {hostile}/builtin/d.npz --epochs 1 --model cvae --set hidden=[8] --set batch=8 -o {tmp_path}/m"):
        result = runner.invoke(app, args.split())
        assert result.exit_code == 0, result.output


def test_a_given_task_must_match_the_file(hostile, untouched, tmp_path):
    message = _one_error(runner.invoke(app, ["trajectory", f"{hostile}/user/p.npz", "--task", "sphere",
                                             "-o", f"{tmp_path}/t.json"]))
    assert "made for another task" in message


# ---------------------------------------------------------------------- one writer per output
HOLDER = textwrap.dedent("""
    import sys, time
    from manifoldgen.io import output_lock
    with output_lock(sys.argv[1]):
        print("held", flush=True)
        time.sleep(60)
""")


@pytest.fixture
def held(tmp_path):
    """``held(path)``: another process holding the output lock of ``path``; returns its pid."""
    started = []

    def hold(path: Path) -> int:
        process = subprocess.Popen([sys.executable, "-c", HOLDER, str(path)], stdout=subprocess.PIPE, text=True,
                                   env={**os.environ, "PYTHONPATH": str(SRC)})
        started.append(process)
        assert process.stdout.readline().strip() == "held"
        return process.pid
    yield hold
    for process in started:
        process.kill()
        process.wait()


def test_a_second_writer_is_refused(held, tmp_path, tmp_path_factory, panda_task):
    from manifoldgen.data import collect

    dataset = tmp_path_factory.mktemp("data") / "d.npz"
    collect(panda_task, 40, 0, dataset, progress=False)
    out, bench = tmp_path / "x.npz", tmp_path / "b"
    pid = held(out)
    message = _one_error(runner.invoke(app, ["collect", "pose", "--per-condition", "5", "-o", str(out)]))
    assert f"process {pid}" in message and f"{out}.lock" in message
    pid = held(bench)
    message = _one_error(runner.invoke(app, ["bench", "plan", "pose", "--scene", "wall", "-m", "rrtconnect@project",
                                             "--runs", "1", "-o", str(bench)]))
    assert f"process {pid}" in message and f"{bench}.lock" in message
    model = tmp_path / "m"
    pid = held(model)
    message = _one_error(runner.invoke(app, ["train", str(dataset), "--model", "cvae", "--epochs", "1", "-o",
                                             str(model)]))
    assert f"process {pid}" in message and f"{model}.lock" in message
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.lock", "m.lock", "x.npz.lock"], "only the holders' locks"
    with output_lock(tmp_path / "y"), pytest.raises(ManifoldgenError, match=f"process {os.getpid()}"):
        with output_lock(tmp_path / "y"):
            pass


def test_a_stale_lock_is_taken_over(tmp_path):
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    out = tmp_path / "x.npz"
    Path(f"{out}.lock").write_text(gone.stdout)  # left by a writer that was killed
    result = runner.invoke(app, ["collect", "pose", "--per-condition", "5", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert out.is_file() and not Path(f"{out}.lock").exists()


# ---------------------------------------------------------------------- labels are names
@pytest.mark.parametrize("label", ["DIR/keep", "../../x", ".hidden", "a..b", "a b"])
def test_a_label_that_is_not_a_plain_name_is_refused(label, tmp_path):
    out = tmp_path / "out"
    (tmp_path / "DIR").mkdir()
    message = _one_error(runner.invoke(app, ["bench", "plan", "pose", "--scene", "wall", "-m",
                                             f"{label}=rrtconnect@project", "--snapshots", "-o", str(out)]))
    assert "not a plain name" in message and label in message
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["DIR"], "nothing written"


def test_plain_labels_pass():
    assert Method.parse("cvae-1.5_x+y:z=rrtconnect@project").label == "cvae-1.5_x+y:z"
    assert Method.parse("rrtconnect@project,batch=8").label == "rrtconnect@project,batch=8"


# ---------------------------------------------------------------------- the viewer's websocket
def test_origin_rule():
    assert origin_allowed(None, "127.0.0.1:8080")  # no browser
    assert origin_allowed("http://127.0.0.1:8080", "127.0.0.1:8080")
    assert origin_allowed("http://localhost:9000", "localhost:9000")  # through a tunnel
    assert origin_allowed("http://[::1]:8080", "[::1]:8080")
    assert origin_allowed("http://10.1.2.3:8080", "10.1.2.3:8080", "0.0.0.0")
    assert not origin_allowed("http://evil.example", "127.0.0.1:8080")
    assert not origin_allowed("http://evil.example:8080", "evil.example:8080")  # DNS rebinding
    assert not origin_allowed("http://localhost:3000", "localhost:8080")  # another local site
    assert not origin_allowed("null", "127.0.0.1:8080")
    assert not origin_allowed("http://127.0.0.1:8080", None)


def test_the_viewer_closes_a_foreign_origin_before_sending_anything():
    server = start_server("127.0.0.1", free_port("127.0.0.1", 8700))
    port = server.get_port()
    try:
        def first_frame(origin: str):
            with connect(f"ws://127.0.0.1:{port}", origin=origin, subprotocols=[f"viser-v{viser.__version__}"],
                         open_timeout=10) as ws:
                try:
                    return ws.recv(timeout=10)
                except ConnectionClosed as exc:
                    return exc.rcvd.code
        assert first_frame("http://evil.example") == ORIGIN_REFUSED
        assert isinstance(first_frame(f"http://127.0.0.1:{port}"), bytes)  # the scene
    finally:
        stop_server(server)
