"""Named tasks: a robot, its planning group, a constraint and its condition values.

``TASKS[name][robot]`` is a factory returning a :class:`Task`; :func:`get_task` resolves
names with clear errors. Pose tasks for panda, pr2 and centauro live in ``pose.py``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from manifoldgen.constraints import Condition, Constraint
from manifoldgen.errors import ManifoldgenError, unknown_name
from manifoldgen.robot import Robot, resolve_robot


@dataclass
class Task:
    """A robot with a constraint; ``home`` is a valid configuration used as an example."""

    name: str
    robot: Robot
    constraint: Constraint
    home: np.ndarray  # (n,) a configuration that satisfies the constraint at home_condition
    home_condition: np.ndarray  # (k,)
    notes: str = ""
    extras: dict = field(default_factory=dict)

    @property
    def condition(self) -> Condition:
        return self.constraint.condition

    def meta(self) -> dict:
        """The dataset ``meta`` fields that let an outside checker recompute everything."""
        return {"task": self.name, "robot": self.robot.name, "joints": self.robot.joints,
                "locked": self.robot.locked, "floating_base": self.robot.floating_base,
                "constraint": self.constraint.spec(),
                "condition": {"names": list(self.condition.names), "units": list(self.condition.units),
                              "values": np.asarray(self.condition.values).tolist()}}


TASKS: dict[str, dict[str, Callable[[], Task]]] = {}


def register(name: str, robot: str):
    """Decorator registering a task factory under (name, robot)."""
    def wrap(factory: Callable[[], Task]) -> Callable[[], Task]:
        TASKS.setdefault(name, {})[robot] = factory
        return factory
    return wrap


@lru_cache(maxsize=None)
def get_task(name: str, robot: str | None = None) -> Task:
    """The task ``name`` for ``robot`` (default: the task's first robot)."""
    if name not in TASKS:
        raise unknown_name("task", name, list(TASKS))
    robots = TASKS[name]
    robot = robot or next(iter(robots))
    if robot not in robots:
        resolve_robot(robot)  # an unknown robot is reported as such
        raise ManifoldgenError(f"task '{name}' is not defined for robot '{robot}'; "
                               f"robots with it: {', '.join(robots)}")
    return robots[robot]()


from manifoldgen.tasks import pose  # noqa: E402,F401  (registers the pose tasks)

__all__ = ["TASKS", "Task", "get_task", "register"]
