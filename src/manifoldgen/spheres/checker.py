"""The batched numpy collision check with a robot's sphere models (:class:`SphereChecker`): spheres that touch
nothing mean a free state; the pairs they flag, and the geometries without spheres, go to coal."""

from __future__ import annotations

import warnings

import coal
import numpy as np
import pinocchio as pin

from manifoldgen.collision import CollisionChecker
from manifoldgen.robot import as_batch
from manifoldgen.spheres.cache import sphere_model
from manifoldgen.spheres.fit import SphereModel, enclosing_ball, fit_model


TIGHT_SAMPLES, TIGHT_RATE = 200, 0.25  # see SphereChecker._tight


# ---------------------------------------------------------------------------------------------- checking
class SphereChecker:
    """The pairs of a :class:`CollisionChecker` (self pairs from the SRDF / sampled matrix, robot and held
    object vs obstacles) checked with sphere models, batched in numpy.

    Conservative: a configuration coal finds in collision is always in collision here. Obstacle boxes,
    spheres and cylinders, and a held box, sphere or cylinder, are tested exactly against the robot's
    spheres; pairs with a mesh obstacle or a geometry without spheres go to coal (said once, as a warning),
    and so do self pairs whose spheres nearly always touch while their meshes do not (``pairs["tight"]``).
    """

    CHUNK = 1024  # rows per numpy pass

    def __init__(self, checker: CollisionChecker, model: SphereModel | None = None, typical: np.ndarray | None = None):
        """model: the robot's spheres (default :func:`sphere_model`); typical (N, n): states like those to be
        checked (a dataset's rows), besides uniform ones, for finding tight pairs (see ``pairs``)."""
        self.checker = checker
        self.robot = robot = checker.robot
        geom = checker.geom
        model = sphere_model(robot) if model is None else model
        held = fit_model(geom, checker.attached_ids)
        keep = np.isin(held.geometry, checker.attached_ids)
        self.joint = np.concatenate([model.joint, held.joint[keep]])
        self.center = np.concatenate([model.center, held.center[keep]])
        self.radius = np.concatenate([model.radius, held.radius[keep]])
        self.geometry = np.concatenate([model.geometry, held.geometry[keep]])
        robot_objects = len(robot.collision_model.geometryObjects)
        unfitted = (set(range(robot_objects)) - set(model.geometry.tolist())) | set(held.unfitted)
        objects = geom.geometryObjects
        why = dict(zip(model.unfitted, model.reasons)) | dict(zip(held.unfitted, held.reasons))
        # robot and held geometries without spheres, name -> why: coal checks every pair they are in
        self.fallback = {objects[i].name: why.get(i, "no spheres") for i in sorted(unfitted)}
        shapes = {oid: objects[oid].geometry for oid in checker.obstacle_ids}
        exact_obstacles = {oid for oid, s in shapes.items()
                           if not isinstance(s, (coal.Box, coal.Sphere, coal.Cylinder))}
        pairs = [(int(geom.collisionPairs[k].first), int(geom.collisionPairs[k].second))
                 for k in range(len(geom.collisionPairs))]
        # a held box, sphere or cylinder is checked exactly against the robot's spheres (a tray held
        # a centimetre from the gripper would need hundreds of spheres); its spheres serve against obstacles
        held_shapes = {i for i in checker.attached_ids if isinstance(objects[i].geometry, (coal.Box, coal.Sphere,
                                                                                          coal.Cylinder))}
        exact, self_pairs, obstacle_pairs, held_pairs = [], [], [], []
        for a, b in pairs:
            if a in shapes or (a in held_shapes and b not in shapes):
                a, b = b, a  # the obstacle, else the held shape, second
            if {a, b} & (unfitted | exact_obstacles):
                exact.append((a, b))
            elif b in shapes:
                obstacle_pairs.append((a, b))
            elif b in held_shapes and a not in held_shapes:
                held_pairs.append((a, b))
            else:
                self_pairs.append((a, b))
        notes = [f"{objects[o].name} (a mesh obstacle)" for o in sorted(exact_obstacles)]
        notes += [f"{name} (no spheres: {reason})" for name, reason in self.fallback.items()]
        if exact:
            warnings.warn(f"sphere check of {robot.name}: {len(exact)} pairs use coal's exact check: "
                          f"{', '.join(notes)}")
        self._joints = np.unique(self.joint)
        self._slot = np.searchsorted(self._joints, self.joint)  # (S,) index into self._joints
        tight = self._tight(self_pairs, geom, typical)
        self_pairs = [p for p in self_pairs if p not in tight]
        exact += tight
        self._setup_bounds(sorted({g for p in self_pairs for g in p} | {a for a, _ in obstacle_pairs + held_pairs}))
        self._setup_obstacles(objects, obstacle_pairs)
        self._setup_self(self_pairs)
        self._held = [(self._bound_of[a], int(np.searchsorted(self._joints, objects[b].parentJoint)),
                       objects[b].placement.homogeneous, *_primitive(objects[b].geometry)) for a, b in held_pairs]
        self._exact = None
        if exact:
            g = geom.copy()
            g.removeAllCollisionPairs()
            for a, b in exact:
                g.addCollisionPair(pin.CollisionPair(a, b))
            self._exact = (g, pin.GeometryData(g), robot.model.createData())
        self.pairs = {"self": len(self_pairs), "obstacle": len(obstacle_pairs), "held": len(held_pairs),
                      "tight": len(tight), "exact": len(exact)}
        self.exact_pairs = exact  # (a, b) geometry index pairs checked by coal (tight ones included)

    def _tight(self, pairs: list[tuple[int, int]], geom: pin.GeometryModel,
               typical: np.ndarray | None) -> list[tuple[int, int]]:
        """Self pairs whose spheres touch in at least ``TIGHT_RATE`` of the uniform (seeded) or of the
        ``typical`` states where coal finds the pair apart (links that sit close, as a shoulder beside the
        torso): they go to coal."""
        sets = [self.robot.sample_uniform(TIGHT_SAMPLES, np.random.default_rng(0))]
        if typical is not None and len(typical):
            typical = as_batch(typical, self.robot.n)
            sets.append(typical[np.linspace(0, len(typical) - 1, min(len(typical), TIGHT_SAMPLES)).astype(int)])
        return sorted({p for q in sets for p in self._tight_in(pairs, geom, q)})

    def _tight_in(self, pairs: list[tuple[int, int]], geom: pin.GeometryModel, q: np.ndarray) -> list[tuple[int, int]]:
        """The pairs of :meth:`_tight` for the states ``q (N, n)``."""
        world = self._place(self.joint_transforms(q), self.center, self._slot)
        touching = []
        for a, b in pairs:
            ia, ib = np.flatnonzero(self.geometry == a), np.flatnonzero(self.geometry == b)
            d2 = np.sum((world[:, ia, None] - world[:, None, ib]) ** 2, axis=-1)
            touching.append(np.any(d2 <= (self.radius[ia, None] + self.radius[None, ib]) ** 2, axis=(1, 2)))
        candidates = [k for k, t in enumerate(touching) if t.mean() >= TIGHT_RATE]
        if not candidates:
            return []
        g = geom.copy()
        g.removeAllCollisionPairs()
        for k in candidates:
            g.addCollisionPair(pin.CollisionPair(*pairs[k]))
        data, gdata = self.robot.model.createData(), pin.GeometryData(g)
        apart = np.zeros((len(q), len(candidates)), bool)
        for i, row in enumerate(self.robot.to_pinocchio(q)):
            pin.computeCollisions(self.robot.model, data, g, gdata, row, False)
            apart[i] = [not r.isCollision() for r in gdata.collisionResults]
        return [pairs[k] for j, k in enumerate(candidates)
                if apart[:, j].any() and touching[k][apart[:, j]].mean() >= TIGHT_RATE]

    def _setup_bounds(self, geoms: list[int]) -> None:
        """Bounding balls of each paired geometry's spheres, for a first cull: (G, 3) centres in the
        geometry's joint frame, (G,) radii, joint slots, and each geometry's sphere indices."""
        self._bound_of = {g: i for i, g in enumerate(geoms)}
        self._members, centers, radii = [], [], []
        for g in geoms:
            idx = np.flatnonzero(self.geometry == g)
            c, _ = enclosing_ball(self.center[idx])
            self._members.append(idx)
            centers.append(c)
            radii.append(float(np.max(np.linalg.norm(self.center[idx] - c, axis=1) + self.radius[idx])))
        self._bound_center = np.array(centers).reshape(-1, 3)
        self._bound_radius = np.array(radii)
        self._bound_slot = np.searchsorted(self._joints, [self.joint[m[0]] for m in self._members]).astype(int)

    def _setup_obstacles(self, objects, pairs: list[tuple[int, int]]) -> None:
        """Per obstacle kind: placements, sizes, and which geometries each obstacle is checked against."""
        self._obstacles = []
        for kind in (coal.Box, coal.Sphere, coal.Cylinder):
            ids = sorted({b for _, b in pairs if isinstance(objects[b].geometry, kind)})
            if not ids:
                continue
            mask = np.zeros((len(self._members), len(ids)), bool)  # (G, O)
            for a, b in pairs:
                if b in ids:
                    mask[self._bound_of[a], ids.index(b)] = True
            size = np.array([_primitive(objects[b].geometry)[1] for b in ids])
            pose = np.array([objects[b].placement.homogeneous for b in ids])
            rot = pose[:, :3, :3].transpose(1, 0, 2).reshape(3, -1)  # (3, 3 O): x @ rot = every x R_o
            offset = np.einsum("oj,oji->oi", pose[:, :3, 3], pose[:, :3, :3])  # (O, 3): p_o R_o
            self._obstacles.append((kind, mask, rot, offset, size))

    def _setup_self(self, pairs: list[tuple[int, int]]) -> None:
        """Each self pair's bounding-ball slots."""
        self._pair_a = np.array([self._bound_of[a] for a, _ in pairs], int)
        self._pair_b = np.array([self._bound_of[b] for _, b in pairs], int)

    def in_collision(self, q: np.ndarray) -> np.ndarray:
        """(B,) bool: True where some sphere of a checked pair touches the other side (conservative)."""
        q = as_batch(q, self.robot.n)
        out = np.zeros(len(q), bool)
        for start in range(0, len(q), self.CHUNK):
            out[start:start + self.CHUNK] = self._chunk(q[start:start + self.CHUNK])
        return out

    def joint_transforms(self, q: np.ndarray) -> np.ndarray:
        """(B, J, 4, 4) world transforms of the joints that carry spheres (``np.unique(joint)`` order)."""
        world = self.robot.joint_poses(q, [int(j) for j in self._joints if j > 0])
        eye = np.broadcast_to(np.eye(4), (len(q), 4, 4))
        return np.stack([world.get(int(j), eye) for j in self._joints], 1)

    def centers(self, q: np.ndarray) -> np.ndarray:
        """(B, S, 3) world sphere centres."""
        T = self.joint_transforms(as_batch(q, self.robot.n))
        return self._place(T, self.center, self._slot)

    def _place(self, T: np.ndarray, local: np.ndarray, slot: np.ndarray) -> np.ndarray:
        """(B, P, 3) world points of ``local (P, 3)`` fixed to the joints ``slot (P,)`` of ``T (B, J, 4, 4)``."""
        out = np.empty((len(T), len(local), 3))
        for j in np.unique(slot):
            mine = slot == j
            out[:, mine] = local[mine] @ T[:, j, :3, :3].transpose(0, 2, 1) + T[:, j, None, :3, 3]
        return out

    def _chunk(self, q: np.ndarray) -> np.ndarray:
        T = self.joint_transforms(q)
        world = self._place(T, self.center, self._slot)  # (B, S, 3)
        hit = np.zeros(len(q), bool)
        bound = self._place(T, self._bound_center, self._bound_slot)  # (B, G, 3)
        for kind, mask, rot, offset, size in self._obstacles:
            near = (_gap2(kind, bound, rot, offset, size) <= self._bound_radius[:, None] ** 2) & mask  # (B, G, O)
            for g in np.flatnonzero(near.any(axis=(0, 2))):
                rows = np.flatnonzero(near[:, g].any(1) & ~hit)
                if not len(rows):
                    continue
                idx = self._members[g]
                d2 = _gap2(kind, world[np.ix_(rows, idx)], rot, offset, size)  # (r, s, O)
                hit[rows] |= np.any((d2 <= self.radius[idx, None] ** 2) & near[rows, g][:, None], axis=(1, 2))
        for g, slot, placement, kind, size in self._held:
            rows = np.flatnonzero(~hit)
            T_held = T[rows, slot] @ placement  # (r, 4, 4) world pose of the held shape
            near = _gap_local(kind, _into(bound[rows, g, None], T_held), size)[:, 0] <= self._bound_radius[g] ** 2
            rows, T_held, idx = rows[near], T_held[near], self._members[g]
            d2 = _gap_local(kind, _into(world[np.ix_(rows, idx)], T_held), size)  # (r, s)
            hit[rows] |= np.any(d2 <= self.radius[idx] ** 2, axis=1)
        if len(self._pair_a):
            a, b = self._pair_a, self._pair_b
            gap = np.sum((bound[:, a] - bound[:, b]) ** 2, axis=-1)
            near = (gap <= (self._bound_radius[a] + self._bound_radius[b]) ** 2) & ~hit[:, None]  # (B, P)
            for p in np.flatnonzero(near.any(0)):  # rows found in collision by one pair skip the next ones
                rows = np.flatnonzero(near[:, p] & ~hit)
                if not len(rows):
                    continue
                ia, ib = self._members[a[p]], self._members[b[p]]
                d2 = np.sum((world[np.ix_(rows, ia)][:, :, None] - world[np.ix_(rows, ib)][:, None]) ** 2, axis=-1)
                hit[rows] |= np.any(d2 <= (self.radius[ia, None] + self.radius[None, ib]) ** 2, axis=(1, 2))
        if self._exact is not None:
            geom, gdata, data = self._exact
            rows = np.flatnonzero(~hit)
            for i, row in zip(rows, self.robot.to_pinocchio(q[rows])):
                hit[i] = pin.computeCollisions(self.robot.model, data, geom, gdata, row, True)
        return hit


def _primitive(shape: coal.CollisionGeometry) -> tuple[type, np.ndarray]:
    """A box's, sphere's or cylinder's kind and size (3,): half extents; radius; radius and half length."""
    if isinstance(shape, coal.Box):
        return coal.Box, np.asarray(shape.halfSide, float)
    if isinstance(shape, coal.Sphere):
        return coal.Sphere, np.array([shape.radius, 0.0, 0.0])
    return coal.Cylinder, np.array([shape.radius, shape.halfLength, 0.0])


def _into(points: np.ndarray, T: np.ndarray) -> np.ndarray:
    """(B, P, 3) world points in the frames ``T (B, 4, 4)``."""
    return np.einsum("bpj,bji->bpi", points - T[:, None, :3, 3], T[:, :3, :3])


def _gap2(kind, points: np.ndarray, rot: np.ndarray, offset: np.ndarray, size: np.ndarray) -> np.ndarray:
    """(B, P, O) squared distances from ``points (B, P, 3)`` to O solid boxes (half extents), spheres
    (radius) or cylinders (radius, half length; along z) placed by ``rot (3, 3 O)`` and ``offset (O, 3)``."""
    return _gap_local(kind, (points @ rot).reshape(*points.shape[:2], len(offset), 3) - offset, size)


def _gap_local(kind, local: np.ndarray, size: np.ndarray) -> np.ndarray:
    """(...) squared distances from points ``local (..., 3)`` in a shape's frame to the solid shape of
    ``size (..., 3)`` (see :func:`_primitive`)."""
    if kind is coal.Box:
        gap = np.maximum(np.abs(local) - size, 0)
        return np.sum(gap * gap, axis=-1)
    if kind is coal.Sphere:
        return np.maximum(np.linalg.norm(local, axis=-1) - size[..., 0], 0) ** 2
    radial = np.maximum(np.linalg.norm(local[..., :2], axis=-1) - size[..., 0], 0)
    axial = np.maximum(np.abs(local[..., 2]) - size[..., 1], 0)
    return radial ** 2 + axial ** 2
