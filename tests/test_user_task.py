"""docs/tasks.md end to end: a user's ~20-line constraint and task file through the public CLI only.

collect -> train (with the residual penalty) -> sample -> plan -> trajectory, on xarm7 (a robot no built-in
task uses); every result is rechecked here with pinocchio from the files alone, state by state. The files
name the user's module:Class, so the commands that read them are given the task file (--task).
"""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.dataset import Dataset
from manifoldgen.io import load_npz
from manifoldgen.robot import resolve_robot

pytestmark = pytest.mark.slow  # the quick loop (pytest -m "not slow") leaves this module out

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "user_task"
TASK = str(EXAMPLE / "tool-down-xarm7.toml")
runner = CliRunner()


def _tool_down_ok(meta: dict, q: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(B,) bool: link_eef at world x = y (0.01 m) with its z axis down (0.01), inside the limits."""
    model = pin.buildModelFromUrdf(str(resolve_robot(meta["robot"])[0]))
    data, frame = model.createData(), model.getFrameId(meta["constraint"]["frame"])
    ok = np.zeros(len(q), bool)
    for b in range(len(q)):
        pin.framesForwardKinematics(model, data, q[b])
        M = data.oMf[frame]
        residual = np.array([M.translation[0] - y[b, 0], M.rotation[0, 2], M.rotation[1, 2]])
        inside = np.all(q[b] >= model.lowerPositionLimit - 1e-9) and np.all(q[b] <= model.upperPositionLimit + 1e-9)
        ok[b] = np.abs(residual).max() <= 0.01 and inside
    return ok


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    out = tmp_path_factory.mktemp("user")
    collected = runner.invoke(app, ["collect", TASK, "--per-condition", "200", "-o", str(out / "d.npz")])
    assert collected.exit_code == 0, collected.output
    trained = runner.invoke(app, ["train", str(out / "d.npz"), "--task", TASK, "--model", "cvae", "--epochs", "30", "--set",
                                  "hidden=[64,64]", "-o", str(out / "m")])
    assert trained.exit_code == 0, trained.output
    return out


def test_collect_and_train_a_user_constraint(trained):
    data = Dataset.load(trained / "d.npz")
    assert data.meta["constraint"]["type"] == "tool_down:ToolDownAtX" and data.meta["task"]["robot"]["name"] == "xarm7"
    assert len(data) == 1000 and _tool_down_ok(data.meta, data.q, data.y).all()
    meta, _ = load_npz(trained / "d.npz", ("q",))
    assert meta["task"]["task_file"] == TASK


def test_sample_the_user_model(trained):
    out = trained / "s.npz"
    result = runner.invoke(app, ["sample", str(trained / "m"), "--task", TASK, "--condition", "0.4", "-n", "300",
                                 "--refine", "0", "-o", str(out)])
    assert result.exit_code == 0, result.output
    data = Dataset.load(out)
    raw = _tool_down_ok(data.meta, data.q, data.y).mean()
    assert data.meta["raw_valid_rate"] == pytest.approx(raw, abs=1 / 300)
    assert raw > 0.3  # the residual penalty trained the model onto the user's manifold


def test_plan_the_user_task_with_its_model(trained):
    out = trained / "p.npz"
    result = runner.invoke(app, ["plan", TASK, "--scene", "open", "--sampler", f"cvae:{trained / 'm'}",
                                 "--seed", "0", "--time", "20", "-o", str(out)])
    assert result.exit_code == 0, result.output
    meta, arrays = load_npz(out, ("path",))
    path, resolution = arrays["path"], meta["validation"]["resolution"]
    states = [a + (b - a) * t for a, b in zip(path[:-1], path[1:])
              for t in np.linspace(0, 1, int(np.ceil(np.linalg.norm(b - a) / resolution)) + 1)]
    y = np.full((len(states), 1), meta["condition"][0])
    assert _tool_down_ok(meta, np.array(states), y).all()
    np.testing.assert_allclose(path[0], meta["start"])
    np.testing.assert_allclose(path[-1], meta["goal"])
    timed = runner.invoke(app, ["trajectory", str(out), "--task", TASK, "-o", str(trained / "t.json")])
    assert timed.exit_code == 0 and "100.0% valid" in timed.output, timed.output


def test_the_user_files_need_the_task_file(trained, monkeypatch):
    """Without --task the files are refused in one line; a task file of another constraint is refused; with
    --trust-code the module is imported from PYTHONPATH."""
    alone = runner.invoke(app, ["train", str(trained / "d.npz"), "-o", str(trained / "m2")])
    assert alone.exit_code == 2 and alone.output.count("\n") == 1, alone.output
    assert "tool_down:ToolDownAtX" in alone.output and "--task FILE" in alone.output
    other = runner.invoke(app, ["sample", str(trained / "m"), "--task", str(EXAMPLE / "tool-down-xarm7-builtin.toml"),
                                "--condition", "0.4", "-o", str(trained / "s2.npz")])
    assert other.exit_code == 2 and "made for another task" in other.output, other.output
    assert not (trained / "m2").exists() and not (trained / "s2.npz").exists()
    monkeypatch.syspath_prepend(str(EXAMPLE))
    trusted = runner.invoke(app, ["sample", str(trained / "m"), "--trust-code", "--condition", "0.4", "-n", "20",
                                  "-o", str(trained / "s3.npz")])
    assert trusted.exit_code == 0, trusted.output


def test_the_candidates_of_a_user_task_train_side_by_side_as_in_one_process(trained):
    """A child process imports the user's module from the file this one did and trains the second candidate at
    this process's torch threads while this one trains the first: the same candidates, bit for bit, as one
    process training them in turn."""
    import torch

    from manifoldgen.models import load_model
    from manifoldgen.runtime import TORCH_THREADS, set_threads
    from manifoldgen.selection import select_model
    from manifoldgen.tasks import code_files, load_task_file

    data, task = Dataset.load(trained / "d.npz"), load_task_file(TASK)
    assert code_files(task.spec()) == {"tool_down": str(EXAMPLE / "tool_down.py")}  # so a child imports it
    set_threads(TORCH_THREADS)
    one, two = ([{k: v for k, v in row.items() if k != "seconds"}
                 for row in select_model(data, trained / f"auto{workers}", seed=3, epochs=1, progress=False,
                                         workers=workers, task=task, race_scenes=False)[1]] for workers in (1, 2))
    assert one == two
    for name in ("cvae", "cfm"):
        one, two = (load_model(trained / f"auto{workers}" / "candidates" / name) for workers in (1, 2))
        for key, value in one.state_tensors().items():
            torch.testing.assert_close(two.state_tensors()[key], value, rtol=0, atol=0)


def test_a_child_refuses_a_user_module_found_in_another_file(trained, tmp_path):
    """A child that would import the user's module from a file other than the parent's refuses, in one line."""
    from manifoldgen.errors import ManifoldgenError
    from manifoldgen.tasks import load_task_file, task_in_child

    spec = load_task_file(TASK).spec()
    with pytest.raises(ManifoldgenError, match=f"module tool_down imports {EXAMPLE / 'tool_down.py'} in a child "
                                               f"process, not {tmp_path / 'tool_down.py'}"):
        task_in_child(spec, {"tool_down": str(tmp_path / "tool_down.py")})


def test_loading_a_user_task_imports_no_torch():
    """A user constraint without a Jacobian of its own (torch autograd by default) loads, its home projected onto
    the manifold by central differences, without importing torch (2-3 s a command): ``plan`` and ``collect`` need
    none of it."""
    code = ("import sys; from manifoldgen.tasks import load_task_file; "
            f"task = load_task_file({TASK!r}); "
            "print(float(abs(task.constraint.residual(task.home[None], task.home_condition[None])).max()), "
            "'torch' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    residual, torch_loaded = done.stdout.split()
    assert float(residual) <= 1e-6 and torch_loaded == "False", done.stdout
