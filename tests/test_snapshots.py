"""Robot snapshots along a path (the paper's Figs. 3-6): a PNG strip rendered without a display."""

from __future__ import annotations

from pathlib import Path

import matplotlib.image
import numpy as np
import pytest
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.io import load_npz
from manifoldgen.viz.snapshots import write_snapshots

runner = CliRunner()


@pytest.mark.slow
def test_strip_shows_the_robot_in_every_panel(tmp_path):
    path = tmp_path / "wall.npz"
    result = runner.invoke(app, ["plan", "pose", "--robot", "pr2", "--scene", "wall", "--sampler", "project",
                                 "--seed", "0", "--time", "60", "-o", str(path)])
    assert result.exit_code == 0, result.output
    out = tmp_path / "strip.png"
    result = runner.invoke(app, ["view", str(path), "--snapshots", str(out)])
    assert result.exit_code == 0 and "wrote" in result.output, result.output
    image = matplotlib.image.imread(out)[..., :3]
    assert image.shape[1] > 4 * image.shape[0]
    body = image[int(0.15 * len(image)):]  # below the titles
    for panel in np.array_split(body, 6, axis=1):
        drawn = np.abs(panel - 1.0).max(axis=-1) > 0.1
        assert drawn.mean() > 0.03, "each of t0 ... t5 shows the robot"
    meta, arrays = load_npz(path, ("path",))
    again = write_snapshots(arrays["path"], tmp_path / "again.png", meta=meta, count=3)
    assert matplotlib.image.imread(again).shape[1] < image.shape[1]


def test_snapshots_need_a_path_file(tmp_path):
    rows = tmp_path / "d.npz"
    assert runner.invoke(app, ["collect", "pose", "--per-condition", "5", "-o", str(rows)]).exit_code == 0
    result = runner.invoke(app, ["view", str(rows), "--snapshots", str(tmp_path / "s.png")])
    assert result.exit_code == 2 and "--snapshots needs a path file" in result.output
    assert not Path(tmp_path / "s.png").exists()
