"""Conservative sphere models of a robot's collision geometries, and a batched numpy check with them.

Every robot collision geometry (mesh, box, cylinder, sphere) gets a few spheres whose union covers it:
its surface and the solid it bounds. Then a state whose spheres touch nothing is collision-free for
coal too; a state they flag may still be free (a false positive), so a planner keeps coal for the final
check. How a mesh is covered, and why the cover is complete:

1. Space is cut into *columns*: the cells of ``K_u`` slabs along a direction ``u`` and ``K_v`` slabs along
   a direction ``v`` (``K_v = 1``: plain slabs), each cell unbounded along the third direction.
2. A ball (convex) that holds the whole boundary of a compact set holds the set: each point of the set
   lies between two boundary points on any line through it (the set's extreme points on that line).
3. The boundary of ``S ∩ C`` (solid ``S``, column ``C``) lies in ``(surface ∩ C) ∪ (S ∩ ∂C)``. ``S`` meets
   each infinite edge line of ``C`` in segments whose ends are surface points of ``C``; so by 2 a ball
   holding ``surface ∩ C`` holds ``S`` on those lines, then on ``C``'s faces (their part of ``S`` is
   bounded by surface points and edge segments), then ``S ∩ C``. No inside test is needed: a column has
   no corners.
4. ``surface ∩ C`` is the union of the triangles clipped to ``C``: convex polygons, each the hull of
   its triangle's vertices inside ``C`` and the crossings of its vertex pairs with ``C``'s planes. One
   ball per non-empty column holds those points: centred near their minimal enclosing ball, with radius
   the largest distance to them plus 1e-6 m. It covers by construction, whatever the centre.

An open mesh has no solid; its surface (what coal tests) is covered all the same. The directions are
the mesh's principal axes; of the column counts tried, the fewest spheres whose union is within
``VOLUME_SLACK`` times the solid's volume (or a ``SHELL_SLACK`` thick shell) of the smallest union
found. Boxes are their 12 triangles, cylinders a circumscribed 24-sided prism (which holds the
cylinder), spheres themselves. A geometry that cannot be fitted (another type: capsule, convex, height
field ...; a mesh with no triangles or with non-finite vertices; a fit that fails) gets no spheres, and
its pairs are checked exactly by coal: ``SphereModel.unfitted`` and ``reasons`` say which and why, and
:class:`SphereChecker` says so in one warning (``fallback``). Models are cached under
``collision.cache_dir()/spheres``, keyed by the robot's geometry model and the bytes of its mesh files.
"""

from __future__ import annotations

import hashlib
import json
import warnings
from dataclasses import dataclass
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
from scipy.spatial import ConvexHull, QhullError

from manifoldgen.collision import CollisionChecker, cache_dir
from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import load_npz, save_npz
from manifoldgen.robot import Robot, as_batch

VERSION = 1
COLUMN_COUNTS = tuple((ku, kv) for ku in (1, 2, 3, 4, 6, 8) for kv in (1, 2, 3) if kv <= ku)
# the fewest spheres whose union exceeds the smallest union found by at most this x the solid's volume,
# or by a shell this thick (m) over the surface
VOLUME_SLACK = 0.15
SHELL_SLACK = 0.001
VOLUME_GRID = 20  # grid points along a geometry's longest side, counting union volumes
PRISM_SIDES = 24
TIGHT_SAMPLES, TIGHT_RATE = 200, 0.25  # see SphereChecker._tight
MARGIN = 1e-6  # metres added to every radius (rounding in the plane-edge crossings)


@dataclass(frozen=True)
class SphereModel:
    """Spheres of a robot's collision geometries.

    joint (S,): pinocchio joint id (the geometry's parentJoint); center (S, 3): in that joint's frame;
    radius (S,); geometry (S,): index into the robot's collision model (the checker's geometry model
    starts with the same objects). unfitted: geometry indices with no spheres (checked exactly), and
    reasons: why, one line each. solid_volume, union_volume (G,): per geometry, the solid's volume and its
    spheres' union (m³, estimated on the fitting grid; 0 for unfitted ones).
    """

    joint: np.ndarray
    center: np.ndarray
    radius: np.ndarray
    geometry: np.ndarray
    unfitted: tuple[int, ...]
    solid_volume: np.ndarray
    union_volume: np.ndarray
    reasons: tuple[str, ...] = ()

    def __len__(self) -> int:
        return len(self.radius)

    def counts(self) -> np.ndarray:
        """(G,) spheres per geometry."""
        return np.bincount(self.geometry, minlength=len(self.solid_volume))


# ---------------------------------------------------------------------------------------------- fitting
def triangles_of(geometry: coal.CollisionGeometry) -> np.ndarray | None:
    """(T, 3, 3) closed triangle surface that holds the geometry (in its own frame); None for a sphere
    or an unsupported type."""
    if isinstance(geometry, coal.BVHModelBase):
        vertices = np.asarray(geometry.vertices(), float)
        index = np.array([[t[0], t[1], t[2]] for t in (geometry.tri_indices(i) for i in range(geometry.num_tris))],
                         int).reshape(-1, 3)
        return vertices[index] if len(index) else None
    if isinstance(geometry, coal.Box):
        half = np.asarray(geometry.halfSide, float)
        corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij")).reshape(3, -1).T * half
        quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
        return np.array([corners[[q[0], q[i], q[i + 1]]] for q in quads for i in (1, 2)])
    if isinstance(geometry, coal.Cylinder):
        # a prism whose polygon's inscribed circle is the cylinder's: it holds the cylinder
        r = geometry.radius / np.cos(np.pi / PRISM_SIDES)
        a = 2 * np.pi * np.arange(PRISM_SIDES) / PRISM_SIDES
        ring = np.stack([r * np.cos(a), r * np.sin(a), np.zeros_like(a)], 1)
        lo, hi = ring - [0, 0, geometry.halfLength], ring + [0, 0, geometry.halfLength]
        nxt = np.roll(np.arange(PRISM_SIDES), -1)
        sides = np.concatenate([np.stack([lo, lo[nxt], hi[nxt]], 1), np.stack([lo, hi[nxt], hi], 1)])
        top, bottom = np.array([0, 0, geometry.halfLength]), np.array([0, 0, -geometry.halfLength])
        caps = np.concatenate([np.stack([np.broadcast_to(bottom, ring.shape), ring[nxt] + bottom, ring + bottom], 1),
                               np.stack([np.broadcast_to(top, ring.shape), ring + top, ring[nxt] + top], 1)])
        return np.concatenate([sides, caps])
    return None


def fit_geometry(geometry: coal.CollisionGeometry) -> tuple[np.ndarray, np.ndarray, float, float] | None:
    """Covering spheres of one geometry in its own frame: centers (k, 3), radii (k,), the solid's volume
    and the spheres' union volume (m³); None when it cannot be fitted (:func:`fit_or_reason` says why)."""
    return fit_or_reason(geometry)[0]


def fit_or_reason(geometry: coal.CollisionGeometry) -> tuple[tuple | None, str | None]:
    """(:func:`fit_geometry`'s fit, None), or (None, why the geometry cannot be fitted: one line)."""
    if isinstance(geometry, coal.Sphere):
        if not (np.isfinite(geometry.radius) and geometry.radius >= 0):
            return None, f"sphere radius {geometry.radius}"
        volume = 4 / 3 * np.pi * geometry.radius ** 3
        return (np.zeros((1, 3)), np.array([geometry.radius + MARGIN]), volume, volume), None
    if not isinstance(geometry, (coal.BVHModelBase, coal.Box, coal.Cylinder)):
        return None, f"{type(geometry).__name__} has no sphere fitting"
    tris = triangles_of(geometry)
    if tris is None:
        return None, "its mesh has no triangles"
    if not np.all(np.isfinite(tris)):
        return None, "its mesh has non-finite vertex coordinates"
    try:
        fit = _fit_triangles(tris)
    except (ValueError, QhullError, np.linalg.LinAlgError, MemoryError) as exc:
        return None, f"fitting failed: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}"
    if not (np.all(np.isfinite(fit[0])) and np.all(np.isfinite(fit[1]))):
        return None, "the fit gave non-finite spheres"
    return fit, None


def _fit_triangles(tris: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
    """:func:`fit_geometry` of a closed triangle surface ``tris (T, 3, 3)`` with finite vertices."""
    vertices = tris.reshape(-1, 3)
    solid = _volume(tris)
    extent = np.ptp(vertices, axis=0)
    h = max(float(extent.max()) / VOLUME_GRID, 1e-5)
    _, axes = np.linalg.eigh(np.cov(vertices.T) + 1e-12 * np.eye(3))
    axes = axes[:, ::-1].T  # (3, 3) principal directions, widest spread first
    fits = []
    for iu, iv in ((0, 1), (0, 2)):
        for centers, radii in _columns(tris, axes[iu], axes[iv]):
            fits.append((len(radii), _union_volume(centers, radii, h), centers, radii))
    fits.sort(key=lambda f: (f[0], f[1]))
    area = float(np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1).sum()) / 2
    allowed = min(f[1] for f in fits) + max(VOLUME_SLACK * solid, SHELL_SLACK * area)
    _, union, centers, radii = next(f for f in fits if f[1] <= allowed)
    return centers, radii, solid, union


def _columns(tris: np.ndarray, u: np.ndarray, v: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """For each ``(ku, kv)`` of ``COLUMN_COUNTS``: one ball per non-empty column of ``ku`` slabs along ``u``
    x ``kv`` slabs along ``v`` holding the triangles ``(T, 3, 3)`` clipped to it, as centers (k, 3), radii (k,)."""
    out = []
    valid = np.ones(tris.shape[:2], bool)
    for ku in sorted({ku for ku, _ in COLUMN_COUNTS}):
        slabs = [_clip(tris, valid, u, a, b) for a, b in _cuts(tris @ u, ku)]
        for kv in sorted({kv for k, kv in COLUMN_COUNTS if k == ku}):
            balls = []
            for pa, va in slabs:
                for c, d in _cuts(tris @ v, kv):
                    pc, vc = _clip(pa, va, v, c, d)
                    if vc.any():
                        balls.append(_enclosing_ball(pc[vc]))
            out.append((np.array([c for c, _ in balls]), np.array([r for _, r in balls])))
    return out


def _volume(tris: np.ndarray) -> float:
    """Volume (m³) bounded by a closed triangle surface (T, 3, 3) (by the divergence theorem), or of its
    convex hull when the surface is open (edges not shared by exactly two triangles)."""
    key = np.round(tris / max(np.ptp(tris), 1e-9), 9)
    _, vertex = np.unique(key.reshape(-1, 3), axis=0, return_inverse=True)
    vertex = vertex.reshape(-1, 3)
    edges = np.sort(np.concatenate([vertex[:, [0, 1]], vertex[:, [1, 2]], vertex[:, [2, 0]]]), axis=1)
    _, uses = np.unique(edges, axis=0, return_counts=True)
    if np.all(uses == 2):
        return abs(float(np.einsum("ti,ti->", tris[:, 0], np.cross(tris[:, 1], tris[:, 2])))) / 6
    try:
        return float(ConvexHull(tris.reshape(-1, 3)).volume)
    except QhullError:
        return 0.0


def _cuts(s: np.ndarray, k: int) -> list[tuple[float, float]]:
    """k equal slabs [a, b] spanning the values ``s``."""
    edges = s.min() + np.ptp(s) * np.arange(k + 1) / k
    edges[-1] = s.max()
    return list(zip(edges[:-1], edges[1:]))


def _clip(points: np.ndarray, valid: np.ndarray, d: np.ndarray, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    """Convex polygons ``points (T, m, 3)`` (rows' ``valid (T, m)`` points, any order) clipped to the slab
    ``a <= x . d <= b``: (T', m + m (m - 1), 3) points and mask whose hull per row is the clipped polygon
    (the points inside, and every vertex pair's crossing of either plane). Rows left empty are dropped."""
    s = points @ d
    keep = valid & (s >= a) & (s <= b)
    i, j = np.triu_indices(points.shape[1], 1)
    out, mask = [points], [keep]
    for c in (a, b):
        si, sj = s[:, i] - c, s[:, j] - c
        cross = valid[:, i] & valid[:, j] & (si * sj < 0)
        w = np.where(cross, si / np.where(cross, si - sj, 1), 0)[..., None]
        out.append(points[:, i] + w * (points[:, j] - points[:, i]))
        mask.append(cross)
    points, keep = np.concatenate(out, 1), np.concatenate(mask, 1)
    rows = keep.any(1)
    return points[rows], keep[rows]


def _enclosing_ball(points: np.ndarray, steps: int = 24) -> tuple[np.ndarray, float]:
    """A near-minimal ball holding ``points (P, 3)`` (Badoiu-Clarkson steps from their box's centre); the
    radius is the largest distance from its centre to any point, so the ball holds them all."""
    c = (points.min(0) + points.max(0)) / 2
    for i in range(steps):
        far = points[np.einsum("ij,ij->i", points - c, points - c).argmax()]
        c = c + (far - c) / (i + 4)
    return c, float(np.sqrt(np.einsum("ij,ij->i", points - c, points - c).max())) + MARGIN


def _union_volume(centers: np.ndarray, radii: np.ndarray, h: float) -> float:
    """Volume (m³) of the union of balls, counted on a grid of spacing ``h``."""
    lo, hi = (centers - radii[:, None]).min(0), (centers + radii[:, None]).max(0)
    axes = [np.arange(a, b + h, h) for a, b in zip(lo, hi)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    covered = np.zeros(len(grid), bool)
    for c, r in zip(centers, radii):
        covered |= np.sum((grid - c) ** 2, axis=1) <= r * r
    return float(covered.sum()) * h ** 3


# ---------------------------------------------------------------------------------------------- models
def sphere_model(robot: Robot) -> SphereModel:
    """The robot's sphere model: read from the cache when it was made for these geometries and mesh
    files, else fitted (a few seconds per robot) and cached."""
    stamp = cache_stamp(robot)
    path = cache_dir() / "spheres" / f"{robot.name}-{_digest(stamp)[:16]}.npz"
    cached = read_cache(path, stamp, len(robot.collision_model.geometryObjects))
    if cached is not None:
        return cached
    model = fit_model(robot.collision_model)
    arrays = {k: getattr(model, k) for k in ("joint", "center", "radius", "geometry", "solid_volume",
                                             "union_volume")}
    arrays["unfitted"] = np.array(model.unfitted, int)
    try:
        save_npz(path, {"robot": robot.name, **stamp, "arrays_sha256": _arrays_digest(arrays),
                        "reasons": list(model.reasons)}, **arrays)
    except ManifoldgenError as exc:  # an unwritable cache costs time, not correctness
        warnings.warn(f"sphere model not cached: {exc}")
    return model


def cache_stamp(robot: Robot) -> dict:
    """What a cached model must have been made for: this code's settings and the robot's geometries."""
    return {"version": VERSION, "slack": VOLUME_SLACK, "shell": SHELL_SLACK, "grid": VOLUME_GRID,
            "counts": [list(c) for c in COLUMN_COUNTS], "prism": PRISM_SIDES,
            "geometries_sha256": _geometry_digest(robot.collision_model)}


def fit_model(geom: pin.GeometryModel, objects: list[int] | None = None) -> SphereModel:
    """Spheres of the given objects (default all) of a pinocchio geometry model, in their joints' frames."""
    objects = range(len(geom.geometryObjects)) if objects is None else objects
    joint, center, radius, owner, unfitted, reasons = [], [], [], [], [], []
    solid = np.zeros(len(geom.geometryObjects))
    union = np.zeros(len(geom.geometryObjects))
    for i in objects:
        g = geom.geometryObjects[i]
        fit, why = fit_or_reason(g.geometry)
        if fit is None:
            unfitted.append(i)
            reasons.append(why)
            continue
        c, r, solid[i], union[i] = fit
        placement = g.placement.homogeneous
        center.append(c @ placement[:3, :3].T + placement[:3, 3])
        radius.append(r)
        joint += [g.parentJoint] * len(r)
        owner += [i] * len(r)
    return SphereModel(np.array(joint, int), np.concatenate(center) if center else np.zeros((0, 3)),
                       np.concatenate(radius) if radius else np.zeros(0), np.array(owner, int), tuple(unfitted),
                       solid, union, tuple(reasons))


def _digest(value) -> str:
    return hashlib.sha256(json.dumps(value, sort_keys=True).encode()).hexdigest()


def _geometry_digest(geom: pin.GeometryModel) -> str:
    """Hash of what the spheres depend on: each object's joint, placement, shape and mesh file bytes."""
    parts = []
    for g in geom.geometryObjects:
        shape = g.geometry
        part = [g.name, int(g.parentJoint), np.round(g.placement.homogeneous, 12).tolist(), type(shape).__name__]
        if isinstance(shape, coal.BVHModelBase):
            mesh = Path(g.meshPath)
            part += [hashlib.sha256(mesh.read_bytes()).hexdigest() if mesh.is_file() else g.meshPath,
                     np.asarray(g.meshScale).tolist(), int(shape.num_tris)]
        elif isinstance(shape, coal.Box):
            part.append(np.asarray(shape.halfSide).tolist())
        elif isinstance(shape, coal.Cylinder):
            part += [shape.radius, shape.halfLength]
        elif isinstance(shape, coal.Sphere):
            part.append(shape.radius)
        parts.append(part)
    return _digest(parts)


def _arrays_digest(arrays: dict[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    for k in sorted(arrays):
        h.update(k.encode() + np.ascontiguousarray(arrays[k]).tobytes())
    return h.hexdigest()


def read_cache(path: Path, stamp: dict, objects: int) -> SphereModel | None:
    """The cached model at ``path`` if made for ``stamp`` and intact; None (with a one-line notice when
    a file was there) otherwise."""
    if not path.exists():
        return None
    try:
        meta, arrays = load_npz(path, ("joint", "center", "radius", "geometry", "unfitted", "solid_volume",
                                       "union_volume"))
    except ManifoldgenError as exc:
        return _stale(path, str(exc))
    if any(meta.get(k) != v for k, v in stamp.items()):
        return _stale(path, "made for other geometries or settings")
    if meta.get("arrays_sha256") != _arrays_digest(arrays):
        return _stale(path, "its arrays do not match their checksum")
    S = len(arrays["radius"])
    if (arrays["center"].shape != (S, 3) or arrays["joint"].shape != (S,) or arrays["geometry"].shape != (S,)
            or arrays["solid_volume"].shape != (objects,) or np.any(arrays["geometry"] >= objects)):
        return _stale(path, "its arrays have the wrong shapes")
    unfitted = tuple(int(i) for i in arrays["unfitted"])
    reasons = tuple(meta.get("reasons") or ["no spheres"] * len(unfitted))
    if len(reasons) != len(unfitted):
        return _stale(path, "its reasons do not match its unfitted geometries")
    return SphereModel(arrays["joint"].astype(int), arrays["center"], arrays["radius"],
                       arrays["geometry"].astype(int), unfitted, arrays["solid_volume"], arrays["union_volume"],
                       reasons)


def _stale(path: Path, why: str) -> None:
    warnings.warn(f"sphere model cache {path} is not valid ({why}); recomputing it")
    return None


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
            c, _ = _enclosing_ball(self.center[idx])
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
