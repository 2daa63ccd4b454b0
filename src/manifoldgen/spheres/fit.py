"""Fitting conservative sphere models to a robot's collision geometries.

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

from collections.abc import Callable
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin


COLUMN_COUNTS = tuple((ku, kv) for ku in (1, 2, 3, 4, 6, 8) for kv in (1, 2, 3) if kv <= ku)


# the fewest spheres whose union exceeds the smallest union found by at most this x the solid's volume,
# or by a shell this thick (m) over the surface
VOLUME_SLACK = 0.15


SHELL_SLACK = 0.001


VOLUME_GRID = 20  # grid points along a geometry's longest side, counting union volumes


PRISM_SIDES = 24


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
    from scipy.spatial import QhullError  # here, not at import: reading a cached model needs no scipy (0.2 s)

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
    solid = solid_volume(tris)
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
        slabs = [_compact(*_clip(tris, valid, u, a, b)) for a, b in _cuts(tris @ u, ku)]
        for kv in sorted({kv for k, kv in COLUMN_COUNTS if k == ku}):
            balls = []
            for pa, va in slabs:
                for c, d in _cuts(tris @ v, kv):
                    pc, vc = _clip(pa, va, v, c, d)
                    if vc.any():
                        balls.append(enclosing_ball(pc[vc]))
            out.append((np.array([c for c, _ in balls]), np.array([r for _, r in balls])))
    return out


def solid_volume(tris: np.ndarray) -> float:
    """Volume (m³) bounded by a closed triangle surface (T, 3, 3) (by the divergence theorem), or of its
    convex hull when the surface is open (edges not shared by exactly two triangles)."""
    key = np.round(tris / max(np.ptp(tris), 1e-9), 9)
    _, vertex = np.unique(key.reshape(-1, 3), axis=0, return_inverse=True)
    vertex = vertex.reshape(-1, 3)
    edges = np.sort(np.concatenate([vertex[:, [0, 1]], vertex[:, [1, 2]], vertex[:, [2, 0]]]), axis=1)
    _, uses = np.unique(edges, axis=0, return_counts=True)
    if np.all(uses == 2):
        return abs(float(np.einsum("ti,ti->", tris[:, 0], np.cross(tris[:, 1], tris[:, 2])))) / 6
    from scipy.spatial import ConvexHull, QhullError

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
    near = (np.where(valid, s, np.inf).min(1, initial=np.inf) <= b) & \
        (np.where(valid, s, -np.inf).max(1, initial=-np.inf) >= a)
    points, valid, s = points[near], valid[near], s[near]  # the others lie wholly on one side: left empty
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


def _compact(points: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The polygons ``points (T, m, 3)`` with each row's ``valid (T, m)`` points first, in their order, and the
    columns no row uses dropped (a triangle clipped to a slab keeps at most 5 of its 9: the next clip then pairs
    5 points, not 9)."""
    width = int(valid.sum(1).max()) if len(valid) else 0
    order = np.argsort(~valid, axis=1, kind="stable")[:, :width]
    return np.take_along_axis(points, order[..., None], 1), np.take_along_axis(valid, order, 1)


def enclosing_ball(points: np.ndarray, steps: int = 24) -> tuple[np.ndarray, float]:
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


def fit_model(geom: pin.GeometryModel, objects: list[int] | None = None,
              fitted: Callable[[], None] | None = None) -> SphereModel:
    """Spheres of the given objects (default all) of a pinocchio geometry model, in their joints' frames;
    ``fitted()`` is called after each object (a progress bar's step)."""
    objects = range(len(geom.geometryObjects)) if objects is None else objects
    joint, center, radius, owner, unfitted, reasons = [], [], [], [], [], []
    solid = np.zeros(len(geom.geometryObjects))
    union = np.zeros(len(geom.geometryObjects))
    for i in objects:
        g = geom.geometryObjects[i]
        fit, why = fit_or_reason(g.geometry)
        if fitted is not None:
            fitted()
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
