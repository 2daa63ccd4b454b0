"""The physics check's entry points: a path file or a path of a floating-base robot, executed in MuJoCo."""

from __future__ import annotations

import difflib
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from manifoldgen.errors import ManifoldgenError
from manifoldgen.physics.settings import PhysicsResult, PhysicsSettings
from manifoldgen.physics.simulate import Simulation
from manifoldgen.robot import Robot

if TYPE_CHECKING:
    from manifoldgen.tasks import Task


# ---------------------------------------------------------------------- entry points
def check_path_file(path_file: str | Path, settings: PhysicsSettings | None = None, *,
                    feet: list[str] | None = None, progress: bool = False, task: Task | None = None,
                    trust_code: bool = False) -> PhysicsResult:
    """Rebuild the task from the path file's meta (``task``, ``trust_code``: see
    :func:`~manifoldgen.tasks.task_from_meta`) and execute its ``path (K, n)`` (see :func:`check_path`)."""
    from manifoldgen.query import read_path_file

    meta, path, task = read_path_file(path_file, task, trust_code=trust_code)
    if not meta.get("floating_base"):
        raise ManifoldgenError(f"{path_file} is a path of {meta.get('robot', 'a robot')} with a fixed base; the "
                               "physics check needs a floating-base robot standing on its feet (a balance task's path)")
    balance = balance_feet(meta.get("constraint") or {})
    feet = _given_feet(task.robot, list(feet), balance) if feet else balance
    if not feet:
        raise ManifoldgenError(f"{path_file}: its constraint ({(meta.get('constraint') or {}).get('type')}) names no "
                               "feet; give the foot frames (--feet), or check a balance task's path")
    result = check_path(task.robot, path, feet, settings, progress=progress)
    result.path_file = str(path_file)
    return result


def _given_feet(robot: Robot, feet: list[str], balance: list[str]) -> list[str]:
    """The ``--feet`` given, each a frame of ``robot`` given once; an unknown one is refused naming the frames
    nearest to it, else the balance constraint's feet."""
    names = [frame.name for frame in robot.model.frames]
    for i, foot in enumerate(feet):
        if foot in feet[:i]:
            raise ManifoldgenError(f"foot frame '{foot}' is given twice; give each foot once")
        if foot not in names:
            close = difflib.get_close_matches(foot, names, n=3)
            hint = (f"did you mean {', '.join(close)}?" if close else
                    f"the balance constraint's feet are {', '.join(balance)}" if balance else
                    f"`manifoldgen robots {robot.name}` lists its frames")
            raise ManifoldgenError(f"unknown frame '{foot}' for robot {robot.name}, given as a foot; {hint}")
    return feet


def balance_feet(spec: dict) -> list[str]:
    """The foot frames of the first ``balance`` constraint in a constraint spec (nested sets searched)."""
    if spec.get("type") == "balance":
        return list(spec["feet"])
    for part in spec.get("parts", []):
        if found := balance_feet(part):
            return found
    return []


def check_path(robot: Robot, path: np.ndarray, feet: list[str], settings: PhysicsSettings | None = None, *,
               progress: bool = False) -> PhysicsResult:
    """Execute ``path (K, n)`` of a floating-base ``robot`` standing on ``feet`` (frame names) in MuJoCo."""
    settings = settings or PhysicsSettings()
    path = np.asarray(path, float)
    if not robot.floating_base:
        raise ManifoldgenError(f"robot {robot.name} has a fixed base; the physics check needs a floating base")
    if path.ndim != 2 or path.shape[1] != robot.n or len(path) < 1 or not np.isfinite(path).all():
        raise ManifoldgenError(f"the path must be a finite (K, {robot.n}) array for {robot.name}, got {path.shape}")
    wall, cpu = time.perf_counter(), time.process_time()
    sim = Simulation(robot, feet, settings, path[0])
    result = sim.run(path, progress)
    result.wall_s, result.cpu_s = time.perf_counter() - wall, time.process_time() - cpu
    return result
