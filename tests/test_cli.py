"""The collect command and its one-line errors."""

import numpy as np
import pytest
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.dataset import Dataset

runner = CliRunner()


def test_collect_writes_a_valid_dataset(tmp_path, panda_task):
    out = tmp_path / "pose.npz"
    result = runner.invoke(app, ["collect", "pose", "--robot", "panda", "--per-condition", "20", "--seed", "0",
                                 "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "120 rows" in result.output
    d = Dataset.load(out)
    assert panda_task.constraint.satisfied(d.q, d.y).all()


def test_collect_at_chosen_conditions_and_strict_range(tmp_path):
    out = tmp_path / "c.npz"
    ok = runner.invoke(app, ["collect", "pose", "--per-condition", "10", "--condition", "0.45", "-o", str(out)])
    assert ok.exit_code == 0, ok.output
    np.testing.assert_allclose(Dataset.load(out).y, 0.45)
    wide = tmp_path / "wide.npz"  # another output: a finished one made with other settings is never replaced
    warn = runner.invoke(app, ["collect", "pose", "--per-condition", "5", "--condition", "0.72", "-o", str(wide)])
    assert warn.exit_code == 0 and "outside the trained range" in warn.output
    strict = runner.invoke(app, ["collect", "pose", "--per-condition", "5", "--condition", "0.72", "--strict",
                                 "-o", str(tmp_path / "strict.npz")])
    assert strict.exit_code == 2 and "outside the trained range" in strict.output


@pytest.mark.parametrize("args, message", [
    (["collect", "pose", "--robot", "ur99"], "unknown robot 'ur99'"),
    (["collect", "poze"], "unknown task 'poze'"),
    (["collect", "pose", "--robot", "baxter"], "not defined for robot 'baxter'"),
    (["collect", "pose", "--per-condition", "0"], "must be positive"),
    (["collect", "pose", "--per-condition", "-3"], "must be positive"),
])
def test_bad_input_is_one_clear_line(args, message, tmp_path):
    result = runner.invoke(app, [*args, "-o", str(tmp_path / "x.npz")])
    assert result.exit_code == 2
    assert message in result.output and "Traceback" not in result.output


def test_missing_output_directory(tmp_path):
    result = runner.invoke(app, ["collect", "pose", "--per-condition", "5", "-o", str(tmp_path / "no" / "x.npz")])
    assert result.exit_code == 2 and "does not exist" in result.output


def test_tasks_lists_every_robot_with_its_range():
    result = runner.invoke(app, ["tasks"], terminal_width=200)
    assert result.exit_code == 0, result.output
    for task, robot, low, high in [("pose", "panda", "0.2", "0.7"), ("pose", "pr2", "0.5", "1"),
                                   ("pose", "centauro", "-0.2", "0.3"), ("balance", "centauro", "0.7", "0.85"),
                                   ("balance", "talos", "0.94", "1.02")]:
        line = next(line for line in result.output.splitlines() if line.startswith(task) and f" {robot} " in line)
        assert f"[{low}, {high}] m" in line
    for robot in ("pr2", "baxter"):
        line = next(line for line in result.output.splitlines() if line.startswith("dualarm") and f" {robot} " in line)
        assert "distance in [0.2, 0.7] m, pitch in [-0.785398, 1.5708] rad" in line


def test_the_command_line_starts_without_torch_numpy_or_the_compiled_core():
    """``manifoldgen --help`` and the model and planner names it lists import none of the heavy libraries."""
    import subprocess
    import sys

    code = ("import sys; from manifoldgen.cli import app\n"
            "try:\n    app(['train', '--help'])\nexcept SystemExit:\n    pass\n"
            "print(sorted({'torch', 'numpy', 'manifoldgen_core', 'pinocchio'} & set(sys.modules)))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip().splitlines()[-1] == "[]"
    assert "cvae, cgan, wgan, flow, cfm" in done.stdout
