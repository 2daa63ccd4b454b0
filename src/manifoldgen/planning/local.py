"""Local planners: the motion from one configuration toward another.

``interpolate`` checks the straight segment every ``resolution`` rad for collision and
constraint tolerance (MoveIt with path constraints, the paper). ``project`` walks toward
the target in steps of at most ``step`` rad, projecting every step onto the manifold
(CBiRRT, OMPL's ProjectedStateSpace), each short segment checked like ``interpolate``. Checks run
on whole segments at once: one ``violation`` call, then collisions along the valid
prefix in order, stopping at the first. Intermediate states must stay within
``(1 - margin)`` of the tolerance, so that the final dense validation (finer resolution)
almost never finds a state between two checked ones outside it.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np

from manifoldgen.collision import CollisionChecker
from manifoldgen.constraints import Constraint, project
from manifoldgen.errors import ManifoldgenError


class LocalPlanner(ABC):
    """Valid motions on the manifold of ``y`` between configurations (n,)."""

    name: ClassVar[str]

    def __init__(self, constraint: Constraint, y: np.ndarray, checker: CollisionChecker | None,
                 resolution: float = 0.05, *, margin: float = 0.05, partial: bool = True, step: float = 0.4):
        if resolution <= 0 or step <= 0 or not 0 <= margin < 1:
            raise ManifoldgenError(f"local planner needs resolution > 0, step > 0 and 0 <= margin < 1, got "
                                   f"{resolution}, {step}, {margin}")
        self.constraint, self.checker = constraint, checker
        self.y = np.asarray(y, dtype=float).reshape(constraint.condition.k)
        self.resolution, self.margin, self.partial, self.step = resolution, margin, partial, step
        self.states_checked = 0
        self.projections = 0

    def valid_prefix(self, states: np.ndarray, last_is_node: bool) -> int:
        """How many leading rows of ``states (B, n)`` are valid; the last row, when it is a
        tree node (already a valid state), needs the plain tolerance, the others the margin."""
        robot, B = self.constraint.robot, len(states)
        limit = np.full(B, 1.0 - self.margin)
        if last_is_node:
            limit[-1] = 1.0
        ok = (self.constraint.violation(states, self.y) <= limit) & robot.within_limits(states)
        G = self.constraint.inequality(states, self.y)
        if G.shape[1]:
            ok &= np.all(G <= 0, axis=1)
        count = int(np.argmin(ok)) if not ok.all() else B
        self.states_checked += count
        if self.checker is not None and count:
            count = self.checker.first_collision(states[:count])
        return count

    def first_valid(self, starts: np.ndarray, ends: np.ndarray) -> int:
        """Index of the first straight segment ``starts[i] -> ends[i]`` ((m, n) each; the ends are
        valid states) that is valid all along, or -1. The first segment is checked alone (it
        usually passes), the others together: one constraint evaluation, then collisions
        segment by segment in order."""
        if self._all_valid([self.segment_states(starts[0], ends[0])]) == 0:
            return 0
        if len(starts) == 1:
            return -1
        i = self._all_valid([self.segment_states(a, b) for a, b in zip(starts[1:], ends[1:])])
        return -1 if i < 0 else i + 1

    def _all_valid(self, pieces: list[np.ndarray]) -> int:
        """Index of the first of ``pieces`` (states after a valid node, ending at a valid state)
        whose every state is valid, or -1."""
        sizes = np.array([len(p) for p in pieces])
        states, last = np.concatenate(pieces), np.cumsum(sizes) - 1
        limit = np.full(len(states), 1.0 - self.margin)
        limit[last] = 1.0
        ok = (self.constraint.violation(states, self.y) <= limit) & self.constraint.robot.within_limits(states)
        G = self.constraint.inequality(states, self.y)
        if G.shape[1]:
            ok &= np.all(G <= 0, axis=1)
        self.states_checked += len(states)
        for i in np.flatnonzero(np.logical_and.reduceat(ok, last - sizes + 1)):
            if self.checker is None or self.checker.first_collision(pieces[i]) == sizes[i]:
                return int(i)
        return -1

    def segment_states(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(k, n) states every ``resolution`` from ``a`` (excluded) to ``b`` (included)."""
        k = max(1, int(np.ceil(np.linalg.norm(b - a) / self.resolution)))
        return a + (b - a) * (np.arange(1, k + 1) / k)[:, None]

    @abstractmethod
    def steer(self, a: np.ndarray, b: np.ndarray, max_distance: float = np.inf) -> tuple[np.ndarray, bool]:
        """A valid motion from ``a`` toward ``b``, at most ``max_distance`` long (straight
        pieces between the returned waypoints): waypoints (K, n) after ``a`` (K = 0: no
        progress), and whether the last one is ``b``."""

    def connect(self, a: np.ndarray, b: np.ndarray) -> np.ndarray | None:
        """Waypoints (K, n) after ``a`` ending at ``b`` when the whole motion is valid, else None."""
        waypoints, reached = self.steer(a, b)
        return waypoints if reached else None


class Interpolate(LocalPlanner):
    """Straight segments, checked every ``resolution`` (constraint tolerance and collision)."""

    name = "interpolate"

    def steer(self, a, b, max_distance=np.inf):
        distance = float(np.linalg.norm(b - a))
        reach = distance <= max_distance
        end = b if reach else a + (b - a) * (max_distance / distance)
        states = self.segment_states(a, end)
        count = self.valid_prefix(states, last_is_node=reach)
        if count == len(states):
            return end[None], reach
        if self.partial and count:
            return states[count - 1:count], False
        return states[:0], False


class Project(LocalPlanner):
    """Steps toward the target, each projected onto the manifold and checked; a step whose
    segment fails is retried at half the length (down to ``resolution``), and steps grow
    back to ``step`` after a success, so the walk is long-legged where the manifold is flat."""

    name = "project"
    precision: float = 0.01  # projections converge to this fraction of the smallest tolerance
    max_iters: int = 20

    def steer(self, a, b, max_distance=np.inf):
        waypoints, q, travelled, length = [], a, 0.0, self.step
        while travelled < max_distance:
            gap = float(np.linalg.norm(b - q))
            if gap <= length and self.constraint.violation(b, self.y)[0] <= 1.0:
                if self._whole(q, b):
                    waypoints.append(b)
                    return np.array(waypoints), True
            else:
                target = q + (b - q) * min(1.0, length / max(gap, 1e-12))
                projected = project(self.constraint, target[None], self.y, max_iters=self.max_iters,
                                    tol=self.precision * float(self.constraint.tolerance.min()))
                self.projections += 1
                nxt = projected.q[0]
                moved = float(np.linalg.norm(nxt - q))
                if not projected.converged[0] or moved > 2 * length or moved < 1e-9 or np.linalg.norm(b - nxt) >= gap:
                    break  # the manifold leads no closer to b from here
                if self._whole(q, nxt):
                    waypoints.append(nxt)
                    travelled += moved
                    q, length = nxt, min(self.step, 2 * length)
                    continue
            if length / 2 < self.resolution:
                break
            length /= 2
        return (np.array(waypoints) if waypoints else np.zeros((0, len(a)))), False

    def _whole(self, a: np.ndarray, b: np.ndarray) -> bool:
        states = self.segment_states(a, b)
        return self.valid_prefix(states, last_is_node=True) == len(states)


LOCAL_PLANNERS: dict[str, type[LocalPlanner]] = {"interpolate": Interpolate, "project": Project}


def make_local(name: str, constraint: Constraint, y: np.ndarray, checker: CollisionChecker | None,
               resolution: float, **options) -> LocalPlanner:
    """The local planner registered as ``name`` (see :data:`LOCAL_PLANNERS`)."""
    if name not in LOCAL_PLANNERS:
        raise ManifoldgenError(f"unknown local planner '{name}'; known: {', '.join(LOCAL_PLANNERS)}")
    return LOCAL_PLANNERS[name](constraint, y, checker, resolution, **options)
