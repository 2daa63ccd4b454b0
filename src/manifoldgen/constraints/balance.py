"""Static balance (paper Section V-D): feet fixed on the ground, centre of mass over the support polygon.

Equalities (B, 3F [+ 3F] + 1): each foot frame at its fixed world position, with ``flat`` feet also at
its fixed world rotation (``log3(R_fixed^T R(q))``), and the base frame's height = y. Inequalities
(B, edges): the signed distance of the CoM's ground projection outside each edge of the support
polygon, plus a margin, must be <= 0. The support polygon is the convex hull of the contact points:
each foot's ``contacts`` (points in the foot frame, e.g. a sole's corners; default: the frame origin)
placed at the fixed foot poses.

The feet may be given as world positions (and rotations), or as a reference ``stance`` (n,): the feet
are fixed where they stand in it. Either way every contact point must touch the ground (z = ``ground``
within the tolerance), and a given stance must itself be balanced (CoM inside with the margin).
"""

from __future__ import annotations

import numpy as np

from manifoldgen.constraints.base import CONSTRAINTS, Condition, Constraint, array_namespace, as_like
from manifoldgen.constraints.so3 import jlog3, log3
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
    """Feet fixed (positions ``foot_positions (F, 3)`` or where they stand in ``stance (n,)``; with
    ``flat``, rotations too); the base frame's height is y; CoM inside the contacts' hull less ``margin``."""

    def __init__(self, robot: Robot, feet: list[str], foot_positions=None, base_frame: str | None = None,
                 values=None, margin: float = 0.02, tolerance: float = 0.01, stance=None, flat: bool = False,
                 foot_rotations=None, contacts=None, ground: float = 0.0):
        if base_frame is None or values is None:
            raise ManifoldgenError("balance needs 'base_frame' (the frame whose height is conditioned) and "
                                   "'values' (its training heights, e.g. [[0.9], [1.0]])")
        feet = list(feet)
        for f in (*feet, base_frame):
            robot.frame_id(f)
        self.robot, self.feet, self.base_frame, self.margin = robot, feet, base_frame, float(margin)
        self.flat, self.ground = bool(flat), float(ground)
        if stance is not None:
            stance = np.asarray(stance, float).reshape(-1)
            if stance.shape != (robot.n,):
                raise ManifoldgenError(f"balance stance has {stance.size} values but the group has {robot.n} "
                                       "coordinates; give one value per coordinate (floating base first)")
        if foot_positions is None:
            if stance is None:
                raise ManifoldgenError("balance needs the feet's 'foot_positions' or a reference 'stance' "
                                       "(the feet are fixed where they stand in it)")
            foot_positions = [robot.frame_pose(stance, f)[0][0] for f in feet]
        self.foot_positions = np.asarray(foot_positions, float).reshape(len(feet), 3)
        self.foot_rotations = None
        if self.flat:
            if foot_rotations is None and stance is None:
                raise ManifoldgenError("flat feet need 'foot_rotations' or a reference 'stance'")
            self.foot_rotations = (np.asarray(foot_rotations, float).reshape(len(feet), 3, 3)
                                   if foot_rotations is not None
                                   else np.stack([robot.frame_pose(stance, f)[1][0] for f in feet]))
        local = np.zeros((1, 3)) if contacts is None else np.asarray(contacts, float).reshape(-1, 3)
        if contacts is not None and not self.flat:
            raise ManifoldgenError("balance 'contacts' (points in each foot frame) need flat = true: a foot free "
                                   "to turn moves them; drop 'contacts' for point feet")
        rotations = self.foot_rotations if self.flat else np.broadcast_to(np.eye(3), (len(feet), 3, 3))
        self.contact_points = (self.foot_positions[:, None] + local @ np.transpose(rotations, (0, 2, 1))).reshape(-1, 3)
        self._check_ground(tolerance)
        hull = convex_hull(self.contact_points[:, :2])
        if len(hull) < 3:
            raise ManifoldgenError(f"the feet {feet} give {len(hull)} distinct ground contact point(s) on a line: "
                                   "no support polygon for the CoM margin; give at least three feet not on one "
                                   "line, or flat = true with 'contacts' (each sole's corners in the foot frame)")
        self.hull = hull  # (H, 2) counter-clockwise support polygon
        edges = np.roll(hull, -1, axis=0) - hull
        self._normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1) / np.linalg.norm(edges, axis=1)[:, None]
        self._offsets = np.einsum("ij,ij->i", self._normals, hull)
        self.condition = Condition(("base height",), ("m",), np.asarray(values, float))
        self.tolerance = np.full(3 * len(feet) * (2 if self.flat else 1) + 1, float(tolerance))
        if stance is not None:
            depth = self.com_depth(stance)[0]
            if depth < self.margin:
                com = robot.com(stance)[0]
                where = (f"{-depth:.3f} m outside the support polygon" if depth < 0 else
                         f"only {depth:.3f} m inside the support polygon, less than the {self.margin} m margin")
                raise ManifoldgenError(f"the reference stance's centre of mass ({com[0]:.3f}, {com[1]:.3f}) is {where}: "
                                       "the stance is not balanced; choose a stance with the CoM over the feet"
                                       + (", or a smaller margin" if depth >= 0 else ""))

    def _check_ground(self, tolerance: float) -> None:
        off = np.abs(self.contact_points[:, 2] - self.ground) > tolerance
        if off.any():
            i = int(np.argmax(off))
            per_foot = len(self.contact_points) // len(self.feet)
            raise ManifoldgenError(f"foot '{self.feet[i // per_foot]}' does not touch the ground: its contact point is "
                                   f"at z = {self.contact_points[i, 2]:.4f} m, the ground at {self.ground} m; choose "
                                   "the sole (contact) frame, or a stance with the feet on the ground")

    def spec(self) -> dict:
        """The constructor's arguments, with the fixed foot positions (and rotations) resolved."""
        out = super().spec()
        out["foot_positions"] = self.foot_positions.tolist()
        if self.flat:
            out["foot_rotations"] = self.foot_rotations.tolist()
        return out

    def com_depth(self, q: np.ndarray) -> np.ndarray:
        """(B,) how far (m) the CoM's ground projection lies inside the support polygon (negative: outside)."""
        com = self.robot.com(q)[:, :2]
        return np.min(self._offsets - com @ self._normals.T, axis=1)

    def core_terms(self, y):
        """Its equalities as pose terms in its residual order (each foot's position, then with flat feet each
        foot's rotation, then the base frame's height), and its CoM margin as the support polygon's inequalities
        ``normals . com[x, y] - (offsets - margin) <= 0`` (a ``com_polygon`` term)."""
        identity, frame_id = np.eye(3).reshape(-1).tolist(), self.robot.frame_id
        terms = [{"type": "pose", "frame": foot, "frame_id": frame_id(foot), "rotation": identity,
                  "position_axes": [0, 1, 2], "orientation_axes": [], "y": target.tolist()}
                 for foot, target in zip(self.feet, self.foot_positions)]
        if self.flat:
            terms += [{"type": "pose", "frame": foot, "frame_id": frame_id(foot), "rotation": R.reshape(-1).tolist(),
                       "position_axes": [], "orientation_axes": [0, 1, 2], "y": []}
                      for foot, R in zip(self.feet, self.foot_rotations)]
        terms.append({"type": "pose", "frame": self.base_frame, "frame_id": frame_id(self.base_frame),
                      "rotation": identity, "position_axes": [2], "orientation_axes": [],
                      "y": np.asarray(y, float).tolist()})
        terms.append({"type": "com_polygon", "normals": self._normals.tolist(),
                      "bounds": (self._offsets - self.margin).tolist()})
        return terms

    def jacobian(self, q, y):
        q, y = self.batch(q, y)
        F, J, Fr, Jr = [], [], [], []
        for i, (foot, target) in enumerate(zip(self.feet, self.foot_positions)):
            p, R, Jf = self.robot.frame_jacobian(q, foot)
            F.append(p - target)
            J.append(Jf[:, :3])
            if self.flat:
                err = log3(self.foot_rotations[i].T @ R)
                Fr.append(err)
                Jr.append(jlog3(err) @ np.transpose(R, (0, 2, 1)) @ Jf[:, 3:])
        p, _, Jb = self.robot.frame_jacobian(q, self.base_frame)
        F += Fr + [p[:, 2:] - y]
        J += Jr + [Jb[:, 2:3]]
        return np.concatenate(F, axis=1), np.concatenate(J, axis=1)

    def residual(self, q, y):
        q, y = self.batch(q, y)
        F, Fr = [], []
        for i, (foot, target) in enumerate(zip(self.feet, self.foot_positions)):
            p, R = self.robot.frame_pose(q, foot)
            F.append(p - as_like(target, q))
            if self.flat:
                Fr.append(log3(as_like(self.foot_rotations[i].T, R) @ R))
        F += Fr + [self.robot.frame_pose(q, self.base_frame)[0][:, 2:] - y]
        return array_namespace(q).concat(F, axis=1)

    def inequality(self, q, y):
        q, _ = self.batch(q, y)
        com = self.robot.com(q)[:, :2]
        return com @ as_like(self._normals.T, com) - as_like(self._offsets - self.margin, com)
