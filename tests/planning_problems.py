"""Small planning problems with known answers, for the planner tests.

A point in R^3 ("PointRobot", limits [-2, 2]^3) on a sphere of radius y (OMPL's constrained
planning demo) or on the tilted plane z = y (a 2-D corridor world); obstacles are analytic
(boxes given by their corners) so that the answer is known exactly.
"""

from __future__ import annotations

import numpy as np

from manifoldgen.constraints import Condition, Constraint, array_namespace
from manifoldgen.robot import as_batch


class PointRobot:
    """The part of the Robot interface planners use, for a point in R^3."""

    name = "point"
    joints = ["x", "y", "z"]
    n = 3
    lower = np.full(3, -2.0)
    upper = np.full(3, 2.0)

    def within_limits(self, q, margin=1e-9):
        q = as_batch(q, 3)
        return np.all((q >= self.lower - margin) & (q <= self.upper + margin), axis=1)

    def sample_uniform(self, count, rng):
        return rng.uniform(self.lower, self.upper, size=(count, 3))


class SphereConstraint(Constraint):
    """|q| = y: a sphere of radius y (tolerance 0.01)."""

    def __init__(self):
        self.robot = PointRobot()
        self.condition = Condition(("radius",), ("m",), np.array([[1.0]]))
        self.tolerance = np.array([0.01])

    def residual(self, q, y):
        q, y = self.batch(q, y)
        return np.linalg.norm(q, axis=1, keepdims=True) - y

    def jacobian(self, q, y):
        q, y = self.batch(q, y)
        norm = np.linalg.norm(q, axis=1, keepdims=True)
        return norm - y, (q / np.maximum(norm, 1e-12))[:, None, :]

    def spec(self):
        return {"type": "sphere"}


class PlaneConstraint(Constraint):
    """z = y: a plane (tolerance 0.01); the corridor world lives on it."""

    def __init__(self):
        self.robot = PointRobot()
        self.condition = Condition(("height",), ("m",), np.array([[0.0]]))
        self.tolerance = np.array([0.01])

    def residual(self, q, y):
        q, y = self.batch(q, y)
        return q[:, 2:3] - y

    def jacobian(self, q, y):
        q, y = self.batch(q, y)
        return q[:, 2:3] - y, np.broadcast_to(np.array([[[0.0, 0.0, 1.0]]]), (len(q), 1, 3)).copy()

    def spec(self):
        return {"type": "plane"}


class BoxChecker:
    """Collision checker for a point among axis-aligned boxes ``(low (3,), high (3,))``."""

    def __init__(self, boxes):
        self.boxes = [(np.asarray(lo, float), np.asarray(hi, float)) for lo, hi in boxes]

    def in_collision(self, q):
        q = as_batch(q, 3)
        hit = np.zeros(len(q), dtype=bool)
        for lo, hi in self.boxes:
            hit |= np.all((q >= lo) & (q <= hi), axis=1)
        return hit

    def first_collision(self, q):
        hits = np.flatnonzero(self.in_collision(q))
        return int(hits[0]) if len(hits) else len(as_batch(q, 3))

    def collisions(self, q):
        q = as_batch(q, 3)[0]
        return [("point", f"box{i}") for i, (lo, hi) in enumerate(self.boxes) if np.all((q >= lo) & (q <= hi))]


def sphere_problem():
    """From the south to the north pole of the unit sphere, round a band of obstacles along
    the equator that leaves one gap (around +x): the answer must cross the equator there."""
    band = [([-2, -2, -0.1], [2, -0.25, 0.1]), ([-2, 0.25, -0.1], [2, 2, 0.1]), ([-2, -2, -0.1], [0.5, 2, 0.1])]
    return SphereConstraint(), np.array([1.0]), BoxChecker(band), np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, 1.0])


def corridor_problem():
    """On the plane z = 0: a wall along x = 0 from y = -2 to 1.6 with an opening near y = 1.8;
    start at (-1, 0), goal at (1, 0): the answer must pass through the opening."""
    wall = [([-0.05, -2.0, -0.5], [0.05, 1.6, 0.5])]
    return PlaneConstraint(), np.array([0.0]), BoxChecker(wall), np.array([-1.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])


class DownAndNear(Constraint):
    """A test's own constraint: the frame's z axis points down (residual (B, 2)) and the frame stays within
    ``reach`` of the base along x (inequality (B, 1)); nothing conditioned."""

    def __init__(self, robot, frame, reach=0.6):
        self.robot, self.frame, self.reach = robot, frame, reach
        self.condition = Condition((), (), np.zeros((1, 0)))
        self.tolerance = np.full(2, 0.01)

    def residual(self, q, y):
        q, _ = self.batch(q, y)
        return self.robot.frame_pose(q, self.frame)[1][:, :2, 2]

    def inequality(self, q, y):
        q, _ = self.batch(q, y)
        p = self.robot.frame_pose(q, self.frame)[0]
        return array_namespace(q).concat([p[:, :1] - self.reach], axis=1)
