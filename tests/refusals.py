"""The runner the refusal tables share (tests/test_bad_inputs.py, test_hostile_api.py, test_hostile_cli.py): a case
is a command line or an API call that must be refused in one line naming the problem."""

from __future__ import annotations

import contextlib
import hashlib
import json
import shutil
import signal
from dataclasses import dataclass
from pathlib import Path

import pytest
import safetensors.numpy
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import load_npz, save_npz
from manifoldgen.models.files import document_checksum

runner = CliRunner()


@dataclass
class Case:
    """A command line (``args``: ``{I}`` the inputs folder, ``{O}`` a fresh output folder) or an API call
    (``call(I, O)``), the text its one-line error must hold, and the name of a set-up its table applies first
    (``patch``: a read-only disk, a full one)."""

    id: str
    needle: str
    args: list[str] | None = None
    call: object = None
    patch: str | None = None


def cli(id: str, args: str | list[str], needle: str, patch: str | None = None) -> Case:
    """``args``: a string split at spaces, or a list (for an empty argument)."""
    return Case(id, needle, args=args.split() if isinstance(args, str) else list(args), patch=patch)


def api(id: str, call, needle: str, patch: str | None = None) -> Case:
    return Case(id, needle, call=call, patch=patch)


def digest(root: Path) -> dict[str, str]:
    """Every file below ``root`` by its SHA-256: what a refused case must leave as it was."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def refusal(case: Case, inputs: Path, out: Path) -> str:
    """Run ``case`` and return its message: on the command line, exit code 2 with no traceback or usage text and
    one ``error:`` line, on stderr; through the API, a ManifoldgenError of one line."""
    if case.args is not None:
        result = runner.invoke(app, [a.format(I=inputs, O=out) for a in case.args], terminal_width=400)
        assert result.exit_code == 2 and isinstance(result.exception, SystemExit), result.output
        assert "Traceback" not in result.output and "Usage:" not in result.output, result.output
        errors = [line for line in result.stderr.splitlines() if line.startswith("error: ")]
        assert len(errors) == 1 and "error: " not in result.stdout, result.output
        return errors[0]
    with pytest.raises(ManifoldgenError) as info:
        case.call(inputs, out)
    message = str(info.value)
    assert "\n" not in message, message
    return message


SHORT = 300  # characters a refusal may take at most


def refused_as_told(case: Case, inputs: Path, out: Path) -> str:
    """:func:`refused_cleanly` with the empty output folder ``out``: the message holds the case's needle (``{I}`` and
    ``{O}`` in it: the two folders), is under :data:`SHORT` characters (each folder counted as one: a temporary
    folder's length is the machine's), and nothing was written into ``out``."""
    message = refused_cleanly(case, inputs, out)
    assert case.needle.replace("{I}", str(inputs)).replace("{O}", str(out)) in message, message
    assert len(message.replace(str(inputs), "I").replace(str(out), "O")) < SHORT, message
    assert not list(out.rglob("*")), "a refused command wrote something"
    return message


def refused_cleanly(case: Case, inputs: Path, out: Path) -> str:
    """:func:`refusal`, and no file below ``inputs`` changed: the message."""
    before = digest(inputs)
    message = refusal(case, inputs, out)
    assert digest(inputs) == before, "an input file changed"
    return message


@contextlib.contextmanager
def within(seconds: int):
    """Fail the case with a TimeoutError (a hang) when its body runs past ``seconds``."""
    def late(signum, frame):
        raise TimeoutError(f"still running after {seconds} s: a hang")
    old = signal.signal(signal.SIGALRM, late)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def refused_after(case: Case, inputs: Path, out: Path, setup=None) -> str:
    """:func:`refused_as_told`, after ``setup(inputs, out)`` put files in ``out`` (a user's file, a link, a lock it
    may return, open, to be closed after the case), which the refusal must leave exactly as they were."""
    if setup is None:
        return refused_as_told(case, inputs, out)
    held = setup(inputs, out)
    before, listed = digest(out), sorted(out.rglob("*"))
    try:
        message = refused_cleanly(case, inputs, out)
    finally:
        if held is not None:
            held.close()
    assert case.needle.replace("{I}", str(inputs)).replace("{O}", str(out)) in message, message
    assert len(message.replace(str(inputs), "I").replace(str(out), "O")) < SHORT, message
    assert digest(out) == before, "a refused command changed the files beside its output"
    assert sorted(out.rglob("*")) == listed, "a refused command left files or folders"
    return message


def copied(source: str, name: str):
    """A set-up: the input ``source`` (a file or folder) copied into the case's folder as ``name``."""
    def setup(I, O):
        (shutil.copytree if (I / source).is_dir() else shutil.copy)(I / source, O / name)
    return setup


def ran(args: str | list[str], setup=None):
    """An accepted command line (``{I}``, ``{O}`` as in a case): after ``setup(I, O)``, exit code 0 and no error
    line; returns its output."""
    def run(I, O):
        if setup is not None:
            setup(I, O)
        words = args.split() if isinstance(args, str) else args
        result = runner.invoke(app, [w.replace("{I}", str(I)).replace("{O}", str(O)) for w in words])
        assert result.exit_code == 0 and "error: " not in result.output, result.output
        return result.output
    return run


def reseal(folder: Path, edit=None, weights=None) -> None:
    """Edit the model directory ``folder``'s model.json (``edit(doc)``) and weights (``weights(arrays)``), then
    recompute both checksums: an edit that passes them (they are not signatures) must meet the field checks."""
    doc = json.loads((folder / "model.json").read_text())
    if weights is not None:
        arrays = safetensors.numpy.load((folder / "model.safetensors").read_bytes())
        weights(arrays)
        blob = safetensors.numpy.save(arrays)
        (folder / "model.safetensors").write_bytes(blob)
        doc["weights_sha256"] = hashlib.sha256(blob).hexdigest()
    if edit is not None:
        edit(doc)
    doc["sha256"] = document_checksum(doc)
    (folder / "model.json").write_text(json.dumps(doc))


def edited_npz(source: Path, target: Path, edit=None, arrays=None) -> None:
    """``target``: the .npz ``source`` with its meta changed by ``edit(meta)`` and its arrays by ``arrays(dict)``."""
    meta, found = load_npz(source, ())
    if edit is not None:
        edit(meta)
    if arrays is not None:
        arrays(found)
    save_npz(target, meta, **found)


def set_key(*keys, value):
    """An edit of a meta: ``meta[keys[0]]...[keys[-1]] = value``."""
    def edit(meta):
        for key in keys[:-1]:
            meta = meta[key]
        meta[keys[-1]] = value
    return edit
