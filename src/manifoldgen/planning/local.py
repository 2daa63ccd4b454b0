"""Local planners: the motion from one configuration toward another.

``interpolate`` checks the straight segment every ``resolution`` rad (MoveIt with path
constraints, the paper); it cannot steer toward a far target (the chord leaves the manifold),
so the tree planners extend it through stepping stones: pooled samples within reach.
``project`` walks toward the target in steps of at most ``step`` rad, projecting every step
onto the manifold (CBiRRT, OMPL's ProjectedStateSpace), each short segment checked the same
way. ``direct`` steers straight toward any target without stepping stones (plain RRT; for a space
without a constraint). ``auto``, the default, is ``interpolate`` that walks where straight segments cannot work:
toward targets with no stepping stone within reach, and where a chord leaves the manifold (a
chord that hits an obstacle is not walked: the obstacle blocks a walk too). Every check goes to
the :class:`~manifoldgen.space.ConstrainedSpace`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np

from manifoldgen.errors import ManifoldgenError
from manifoldgen.space import ConstrainedSpace

DEFAULT_LOCAL = "auto"


class LocalPlanner(ABC):
    """Valid motions in ``space`` between configurations (n,).

    resolution: spacing of the checked states along a straight segment (rad); partial:
    a blocked straight segment keeps its valid part; step: longest projected step.
    ``stones``: the planner extends it toward far targets through stepping stones; ``walks``:
    it can walk on the manifold toward any target (:meth:`walk`).
    """

    name: ClassVar[str]
    stones: ClassVar[bool] = False
    walks: ClassVar[bool] = True
    precision: ClassVar[float] = 0.01  # projections converge to this fraction of the smallest tolerance
    max_iters: ClassVar[int] = 20

    def __init__(self, space: ConstrainedSpace, *, resolution: float = 0.05, partial: bool = True,
                 step: float = 0.4):
        if resolution <= 0 or step <= 0:
            raise ManifoldgenError(f"local planner needs resolution > 0 and step > 0, got {resolution}, {step}")
        self.space, self.resolution, self.partial, self.step = space, resolution, partial, step
        self.projections = 0

    def first_valid(self, starts: np.ndarray, ends: np.ndarray) -> int:
        """Index of the first straight segment ``starts[i] -> ends[i]`` ((m, n) each; the ends are
        valid states) that is valid all along, or -1. The first segment is checked alone (it
        usually passes), the others together."""
        if self.space.first_valid_piece([self.segment_states(starts[0], ends[0])]) == 0:
            return 0
        if len(starts) == 1:
            return -1
        i = self.space.first_valid_piece([self.segment_states(a, b) for a, b in zip(starts[1:], ends[1:])])
        return -1 if i < 0 else i + 1

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

    def straight(self, a: np.ndarray, b: np.ndarray, max_distance: float = np.inf) -> tuple[np.ndarray, bool]:
        """The straight segment from ``a`` toward ``b`` (at most ``max_distance``), as :meth:`steer`
        answers: its end when valid all along, else its valid part (``partial``) or nothing."""
        distance = float(np.linalg.norm(b - a))
        reach = distance <= max_distance
        end = b if reach else a + (b - a) * (max_distance / distance)
        states = self.segment_states(a, end)
        count = self.space.valid_prefix(states, last_is_node=reach)
        if count == len(states):
            return end[None], reach
        if self.partial and count:
            return states[count - 1:count], False
        return states[:0], False

    def onto_manifold(self, q: np.ndarray) -> np.ndarray | None:
        """``q (n,)`` projected onto the manifold to ``precision`` x the smallest tolerance (a walk's step, a relaxed
        waypoint), counted in ``projections``; None where the projection does not converge."""
        self.projections += 1
        p = self.space.project(q[None], max_iters=self.max_iters,
                               tol=self.precision * float(self.space.constraint.tolerance.min()))
        return p.q[0] if p.converged[0] else None

    def walk(self, a: np.ndarray, b: np.ndarray, max_distance: float = np.inf, *,
             creep: bool = True) -> tuple[np.ndarray, bool]:
        """A walk on the manifold from ``a`` toward ``b``, as :meth:`steer` answers: steps toward
        ``b``, each projected onto the manifold and checked; a step whose segment fails is retried
        at half the length (down to ``resolution``), and steps grow back to ``step`` after a
        success, so the walk is long-legged where the manifold is flat. ``creep=False`` gives up
        at the first collision instead of creeping up to the obstacle (for connections, which
        keep nothing short of ``b``)."""
        space = self.space
        waypoints, q, travelled, length = [], a, 0.0, self.step
        while travelled < max_distance:
            gap = float(np.linalg.norm(b - q))
            if gap <= length and space.violation(b[None])[0] <= 1.0:
                if self._whole(q, b):
                    waypoints.append(b)
                    return np.array(waypoints), True
                if not creep and space.stop == "collision":
                    break
            else:
                nxt = self.onto_manifold(q + (b - q) * min(1.0, length / max(gap, 1e-12)))
                moved = np.inf if nxt is None else float(np.linalg.norm(nxt - q))
                if nxt is None or moved > 2 * length or moved < 1e-9 or np.linalg.norm(b - nxt) >= gap:
                    break  # the manifold leads no closer to b from here
                if self._whole(q, nxt):
                    waypoints.append(nxt)
                    travelled += moved
                    q, length = nxt, min(self.step, 2 * length)
                    continue
                if not creep and space.stop == "collision":
                    break
            if length / 2 < self.resolution:
                break
            length /= 2
        return (np.array(waypoints) if waypoints else np.zeros((0, len(a)))), False

    def _whole(self, a: np.ndarray, b: np.ndarray) -> bool:
        states = self.segment_states(a, b)
        return self.space.valid_prefix(states, last_is_node=True) == len(states)


class Interpolate(LocalPlanner):
    """Straight segments only (far targets through the planner's stepping stones)."""

    name = "interpolate"
    stones, walks = True, False

    def steer(self, a, b, max_distance=np.inf):
        return self.straight(a, b, max_distance)


class Direct(LocalPlanner):
    """Straight segments of at most the planner's range toward any target, no stepping stones: plain
    RRT steering, for a space without a constraint (the balance-blind baseline)."""

    name = "direct"
    stones, walks = False, False

    def steer(self, a, b, max_distance=np.inf):
        return self.straight(a, b, max_distance)


class Project(LocalPlanner):
    """Walks on the manifold (see :meth:`LocalPlanner.walk`)."""

    name = "project"

    def steer(self, a, b, max_distance=np.inf):
        return self.walk(a, b, max_distance)


class Auto(LocalPlanner):
    """Straight segments through stepping stones; a walk where the chord leaves the manifold
    (and, in the planners, toward targets with no stepping stone within reach)."""

    name = "auto"
    stones = True

    def steer(self, a, b, max_distance=np.inf):
        waypoints, reached = self.straight(a, b, max_distance)
        if reached or self.space.stop != "constraint":
            return waypoints, reached
        return self.walk(a, b, max_distance)

    def connect(self, a, b):
        waypoints, reached = self.straight(a, b)
        if not reached and self.space.stop == "constraint":
            waypoints, reached = self.walk(a, b, creep=False)
        return waypoints if reached else None


LOCAL_PLANNERS: dict[str, type[LocalPlanner]] = {"auto": Auto, "interpolate": Interpolate, "project": Project,
                                                 "direct": Direct}


def make_local(name: str, space: ConstrainedSpace, **options) -> LocalPlanner:
    """The local planner registered as ``name`` (see :data:`LOCAL_PLANNERS`) in ``space``."""
    if name not in LOCAL_PLANNERS:
        raise ManifoldgenError(f"unknown local planner '{name}'; known: {', '.join(LOCAL_PLANNERS)}")
    return LOCAL_PLANNERS[name](space, **options)
