"""Make the inputs of the seventh hostile round's table (tests/test_hostile_round7_table.py) in a pytest folder, in
this process: round 6's inputs (round6/fixtures.py: a path, dataset, model, roadmap, bench folder, balance path,
trajectory, checkpoint), then a sphere path, a trajectory as CSV, a dataset at one condition, copies of the wall scene
and of the user-task example, and the edited and hand-made files (fixtures_more.py). About five seconds on one core."""

from __future__ import annotations

import shutil
from pathlib import Path

from manifoldgen.tasks import BUILTIN_DIR
from round6 import fixtures as round6
from round6.fixtures import mg
from round7 import fixtures_more

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def make(root: Path, path: Path) -> None:
    """Every input of the table in ``root``; ``path``: a path file of the pose task's wall, copied in."""
    round6.make(root, path)
    mg("plan", "sphere", "--scene", "sphere", "--time", 20, "--no-picture", "-o", root / "sph.npz")
    mg("trajectory", root / "path.npz", "-o", root / "traj.csv")
    mg("collect", "pose", "--condition", 0.45, "--per-condition", 10, "--seed", 1, "-o", root / "d1.npz")
    shutil.copytree(EXAMPLES / "user_task", root / "user_task")
    shutil.copy(BUILTIN_DIR / "scenes" / "panda-wall.json", root / "wall.json")
    fixtures_more.make(root)
