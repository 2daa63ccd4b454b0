"""Make the inputs of the sixth hostile round's table (tests/test_hostile_round6_table.py) in a pytest folder, in this
process: the base files through the command line, small (5 rows per condition, a model of hidden=[8] trained one
epoch), then their edits and the hand-made files (fixtures_more.py). A few seconds on one core."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.models import CVAE
from round6 import fixtures_more

runner = CliRunner()
# the resume cases' training, as the case commands give it
TRAIN = ["--model", "cvae", "--epochs", "100000", "--set", "hidden=[8]", "--set", "patience=100000"]


def mg(*args) -> None:
    """Run a command in this process; it must succeed."""
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output


def interrupted_training(data: Path, out: Path) -> None:
    """``out``: the training :data:`TRAIN` of ``data`` stopped by Ctrl-C in its third epoch, its checkpoint kept."""
    step, calls = CVAE._train_step, []

    def interrupted(self, *args):
        calls.append(1)
        if len(calls) == 3:  # one step an epoch: 30 rows in one batch
            raise KeyboardInterrupt
        return step(self, *args)
    CVAE._train_step = interrupted
    try:
        result = runner.invoke(app, ["train", str(data), *TRAIN, "-o", str(out)])
    finally:
        CVAE._train_step = step
    assert result.exit_code == 2 and "--resume" in result.output, result.output
    assert (out / "checkpoint.safetensors").is_file()


def make(root: Path, path: Path) -> None:
    """Every input of the table in ``root``; ``path``: a path file of the pose task's wall, copied in."""
    shutil.copy(path, root / "path.npz")
    mg("collect", "pose", "--per-condition", 5, "--seed", 0, "-o", root / "data.npz")
    mg("train", root / "data.npz", "--model", "cvae", "--epochs", 1, "--set", "hidden=[8]", "-o", root / "model")
    mg("plan", "pose", "--scene", "wall", "--time", 10, "--no-picture", "--roadmap", root / "rm.npz",
       "-o", root / "p2.npz")
    mg("bench", "plan", "pose", "--scene", "wall", "--runs", 2, "--time", 5, "-m", "rrtconnect@project",
       "-o", root / "bench")
    mg("plan", "balance", "--scene", "reach", "--time", 30, "--no-picture", "-o", root / "bal.npz")
    mg("trajectory", root / "path.npz", "-o", root / "traj.json")
    (root / "phys.json").write_text(json.dumps({"generator": "manifoldgen", "kind": "physics", "upright": True}))
    interrupted_training(root / "data.npz", root / "ck")
    fixtures_more.make(root)
