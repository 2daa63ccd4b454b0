"""Static balance (paper Section V-D): feet fixed on the ground, centre of mass over the support polygon.

Equalities (B, 3 * feet + 1): each foot frame at its fixed world position, and the
base height = y. Inequalities (B, edges): the signed distance of the CoM's ground
projection outside each edge of the feet's convex hull, plus a margin, must be <= 0.
"""

from __future__ import annotations

import numpy as np
from array_api_compat import array_namespace

from manifoldgen.constraints.base import CONSTRAINTS, Condition, Constraint, as_like
from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot


def convex_hull(points: np.ndarray) -> np.ndarray:
    """(P, 2) -> (H, 2) hull vertices, counter-clockwise (Andrew's monotone chain)."""
    pts = sorted(set(map(tuple, np.round(np.asarray(points, float), 9))))
    if len(pts) < 3:
        return np.array(pts)

    def turn(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    def half(seq):
        out = []
        for p in seq:
            while len(out) >= 2 and turn(out[-2], out[-1], p) <= 0:
                out.pop()
            out.append(p)
        return out[:-1]
    return np.array(half(pts) + half(pts[::-1]))


@CONSTRAINTS.register("balance")
class BalanceConstraint(Constraint):
    """Feet at ``foot_positions`` (F, 3); the base frame's height is y; CoM inside the feet's hull."""

    def __init__(self, robot: Robot, feet: list[str], foot_positions, base_frame: str,
                 values, margin: float = 0.02, tolerance: float = 0.01):
        for f in (*feet, base_frame):
            robot.frame_id(f)
        self.robot, self.feet, self.base_frame, self.margin = robot, list(feet), base_frame, margin
        self.foot_positions = np.asarray(foot_positions, float).reshape(len(feet), 3)
        hull = convex_hull(self.foot_positions[:, :2])
        if len(hull) < 3:
            raise ManifoldgenError(f"the feet {self.feet} span no support polygon (fewer than 3 non-collinear "
                                   "ground points); give at least three feet, or feet not on one line")
        edges = np.roll(hull, -1, axis=0) - hull
        self._normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1) / np.linalg.norm(edges, axis=1)[:, None]
        self._offsets = np.einsum("ij,ij->i", self._normals, hull)
        self.condition = Condition(("base height",), ("m",), np.asarray(values, float))
        self.tolerance = np.full(3 * len(feet) + 1, tolerance)

    def jacobian(self, q, y):
        q, y = self.batch(q, y)
        F, J = [], []
        for foot, target in zip(self.feet, self.foot_positions):
            p, _, Jf = self.robot.frame_jacobian(q, foot)
            F.append(p - target)
            J.append(Jf[:, :3])
        p, _, Jb = self.robot.frame_jacobian(q, self.base_frame)
        F.append(p[:, 2:] - y)
        J.append(Jb[:, 2:3])
        return np.concatenate(F, axis=1), np.concatenate(J, axis=1)

    def residual(self, q, y):
        q, y = self.batch(q, y)
        F = [self.robot.frame_pose(q, foot)[0] - as_like(target, q) for foot, target in
             zip(self.feet, self.foot_positions)]
        F.append(self.robot.frame_pose(q, self.base_frame)[0][:, 2:] - y)
        return array_namespace(q).concat(F, axis=1)

    def inequality(self, q, y):
        q, _ = self.batch(q, y)
        com = self.robot.com(q)[:, :2]
        return com @ as_like(self._normals.T, com) - as_like(self._offsets - self.margin, com)
