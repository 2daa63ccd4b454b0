"""The seventh hostile round's findings, fixed: a task with no condition collected (it crashed); a user constraint
whose residual() returns a list, whose jacobian() has the wrong shape or whose condition is no Condition, named with
what is wrong (it was blamed on the task file); a user's module raising KeyboardInterrupt and Ctrl-C each said in one
line; a built-in task's name viewed; a sampler batch bounded so that its first row never takes minutes."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

import manifoldgen as mg
from manifoldgen.cli import app
from manifoldgen.dataset import Dataset
from refusals import api, cli, refused_as_told

runner = CliRunner()
GROUP = ", ".join(f'"panda_joint{i}"' for i in range(1, 8))
TASK = f'name = "p7"\nrobot = "panda"\ngroup = [{GROUP}]\n[[constraints]]\ntype = "{{type}}"\n'
MODULE = '''import numpy as np
from manifoldgen.constraints import Condition, Constraint


class C(Constraint):
    def __init__(self, robot, frame="panda_hand_tcp"):
        self.robot, self.frame = robot, frame
        self.condition = Condition(("z",), ("m",), np.asarray([[0.4], [0.5]], float))
        self.tolerance = np.full(1, 0.01)
        {init}

    def residual(self, q, y):
        q, y = self.batch(q, y)
        return {residual}
{more}'''
HEIGHT = "self.robot.frame_pose(q, self.frame)[0][:, 2:3] - y"
USER = {  # module -> (the end of __init__, what residual() returns, more methods)
    "as_list": ("pass", f"({HEIGHT}).tolist()", ""),
    "wide_jacobian": ("pass", HEIGHT, "\n    def jacobian(self, q, y):\n"
                      "        return self.residual(q, y), np.zeros((len(q), 3, 3))\n"),
    "interrupts": ("pass", "self.stop()", "\n    def stop(self):\n        raise KeyboardInterrupt\n"),
    "tuple_condition": ('self.condition = ("z",)', HEIGHT, ""),
}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """Task files: an orientation constraint alone (no condition), and one per misbehaving user module."""
    root = tmp_path_factory.mktemp("inputs")
    (root / "upright.toml").write_text(TASK.format(type="orientation") + 'frame = "panda_hand_tcp"\n'
                                       "axis = [0.0, 0.0, 1.0]\ndirection = [0.0, 0.0, -1.0]\n")
    for name, (init, residual, more) in USER.items():
        (root / f"{name}.py").write_text(MODULE.format(init=init, residual=residual, more=more))
        (root / f"{name}.toml").write_text(TASK.format(type=f"{name}:C"))
    return root


CASES = [
    cli("user-residual-a-list", "collect {I}/as_list.toml --per-condition 5 -o {O}/d.npz",
        "the residual of constraint as_list:C is a list, not an array of shape (256, 1); fix its residual()"),
    cli("user-jacobian-wrong-shape", "collect {I}/wide_jacobian.toml --per-condition 5 -o {O}/d.npz",
        "the jacobian of constraint wide_jacobian:C has shape (1, 3, 3) for one configuration, not (1, 1, 7)"),
    cli("user-condition-a-tuple", "collect {I}/tuple_condition.toml --per-condition 5 -o {O}/d.npz",
        "constraint 'tuple_condition:C': its condition must be a manifoldgen.constraints.Condition, got tuple"),
    api("sampler-batch-over-its-cap", lambda I, O: mg.sampler("pose", "wall", "project", batch=100_001),
        "sampler: batch must be from 1 to 100,000, got 100001"),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_refused_in_one_line_with_nothing_written(case, inputs, tmp_path):
    refused_as_told(case, inputs, tmp_path)


def test_a_task_with_no_condition_is_collected_on_its_constraint(inputs, tmp_path):
    result = runner.invoke(app, ["collect", str(inputs / "upright.toml"), "--per-condition", "8", "-o",
                                 str(tmp_path / "d.npz")])
    assert result.exit_code == 0, result.output
    data = Dataset.load(tmp_path / "d.npz")
    task = mg.load_task(inputs / "upright.toml")
    assert data.q.shape == (8, 7) and data.y.shape == (8, 0)
    assert task.constraint.satisfied(data.q, np.zeros(0)).all()


def test_a_users_keyboard_interrupt_is_one_line_naming_it(inputs, tmp_path):
    result = runner.invoke(app, ["collect", str(inputs / "interrupts.toml"), "--per-condition", "5", "-o",
                                 str(tmp_path / "d.npz")])
    assert result.exit_code == 130 and not list(tmp_path.iterdir()), result.output
    errors = [line for line in result.stderr.splitlines() if line.startswith("error: ")]
    assert errors == [f"error: user code {inputs / 'interrupts.py'}, line 17 raised KeyboardInterrupt; stopped (fix "
                      "that module if Ctrl-C was not pressed)"], result.output


def test_a_built_in_tasks_name_is_viewed(tmp_path):
    result = runner.invoke(app, ["view", "pose", "--export", str(tmp_path / "t.html")])
    assert result.exit_code == 0, result.output
    assert "panda" in (tmp_path / "t.html").read_text() and "wrote" in result.output
