"""``manifoldgen trajectory``: TOPP-RA timing of a path, every sample rechecked, independently too:
the limits from the URDF with pinocchio, the constraint and collisions with the outside checker."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.io import load_npz, save_npz

runner = CliRunner()
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
sys.path.insert(0, str(EXAMPLES))
from check_path import outside_check  # noqa: E402  (the standalone checker users run)


@pytest.fixture(scope="module")
def wall(planned_path) -> Path:
    return planned_path("wall")


def test_trajectory_is_within_limits_and_on_the_manifold(wall, tmp_path, panda_task):
    out = tmp_path / "traj.json"
    result = runner.invoke(app, ["trajectory", str(wall), "--vel-scale", "0.5", "--acc-scale", "0.4", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "100.0% valid" in result.output and " s for a path of " in result.output
    traj = json.loads(out.read_text())
    meta, arrays = load_npz(wall, ("path",))
    assert traj["joint_names"] == meta["joints"]
    t = np.array([p["time_from_start"]["sec"] + 1e-9 * p["time_from_start"]["nanosec"] for p in traj["points"]])
    q, v, a = (np.array([p[key] for p in traj["points"]]) for key in ("positions", "velocities", "accelerations"))
    assert t[0] == 0 and np.all(np.diff(t) > 0) and np.diff(t).max() <= 0.01 + 1e-9
    np.testing.assert_allclose(q[[0, -1]], arrays["path"][[0, -1]], atol=1e-9)
    assert np.abs(v[[0, -1]]).max() < 1e-6

    model = pin.buildModelFromUrdf(str(panda_task.robot.urdf_path))  # the limits, read independently
    ids = [model.joints[model.getJointId(j)] for j in meta["joints"]]
    v_max = np.array([model.velocityLimit[j.idx_v] for j in ids]) * 0.5
    lower = np.array([model.lowerPositionLimit[j.idx_q] for j in ids])
    upper = np.array([model.upperPositionLimit[j.idx_q] for j in ids])
    assert np.all((q >= lower - 1e-9) & (q <= upper + 1e-9))
    assert np.abs(v / v_max).max() <= 1 + 1e-9
    assert np.abs(a / (2 * v_max / 0.5 * 0.4)).max() <= 1 + 1e-9
    assert np.abs(np.gradient(q, t, axis=0) - v).max() < 0.05 * v_max.max()  # velocities match the positions
    duration, length = traj["manifoldgen"]["duration"], traj["manifoldgen"]["path_length"]
    assert duration == pytest.approx(t[-1]) and duration > length / np.linalg.norm(v_max)

    samples = tmp_path / "samples.npz"  # the samples as a path: the outside checker rechecks every chord
    save_npz(samples, meta, path=q)
    check = outside_check(samples)
    assert check["valid"] and check["worst"] <= 1.0, check["line"]
    assert check["states"] >= len(q)


def test_trajectory_csv_layout(wall, tmp_path):
    out = tmp_path / "traj.csv"
    assert runner.invoke(app, ["trajectory", str(wall), "-o", str(out)]).exit_code == 0
    rows = list(csv.reader(out.read_text().splitlines()))
    joints = [f"panda_joint{i}" for i in range(1, 8)]
    assert rows[0] == ["time_from_start"] + [f"{j}.{k}" for k in ("position", "velocity", "acceleration")
                                             for j in joints]
    table = np.array(rows[1:], float)
    assert table.shape[1] == 1 + 3 * 7 and table[0, 0] == 0 and np.all(np.diff(table[:, 0]) > 0)


def test_trajectory_bad_inputs_get_one_line(wall, tmp_path):
    rows = tmp_path / "d.npz"
    save_npz(rows, {"robot": "panda"}, q=np.zeros((2, 7)), y=np.zeros((2, 1)))
    for args, expected in ((["--vel-scale", "0"], "--vel-scale must be in (0, 1]"),
                           (["--acc-scale", "1.5"], "--acc-scale must be in (0, 1]"),
                           (["--dt", "-1"], "--dt must be from 0.0001 to 10 seconds"),
                           (["-o", str(tmp_path / "t.txt")], "-o must end in .json or .csv")):
        command = ["trajectory", str(wall), *args] + ([] if "-o" in args else ["-o", str(tmp_path / "t.json")])
        result = runner.invoke(app, command)
        assert result.exit_code == 2 and expected in result.output and result.output.count("\n") == 1, result.output
    result = runner.invoke(app, ["trajectory", str(rows), "-o", str(tmp_path / "t.json")])
    assert result.exit_code == 2 and "is not a path file" in result.output
