"""Sphere models kept on disk: under ``collision.cache_dir()/spheres``, keyed by the robot's geometry model and
the bytes of its mesh files; a stale or damaged file is refitted. The package ships the models of the robots its
tasks and held-out tasks name (:data:`SHIPPED`, made by ``scripts/ship_spheres.py``), read where the user's cache
has none, so that those robots are never fitted on a machine whose robot files are the ones they were made for."""

from __future__ import annotations

import hashlib
import json
import sys
import warnings
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin

from manifoldgen.collision import cache_dir
from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import load_npz, save_npz
from manifoldgen.progress import progress_bar
from manifoldgen.robot import Robot
from manifoldgen.spheres.fit import (COLUMN_COUNTS, PRISM_SIDES, SHELL_SLACK, VOLUME_GRID, VOLUME_SLACK, SphereModel,
                                     fit_model)


VERSION = 1
SHIPPED = Path(__file__).resolve().parent.parent / "data" / "spheres"  # the package's fitted models (read only)


# ---------------------------------------------------------------------------------------------- models
def sphere_model(robot: Robot) -> SphereModel:
    """The robot's sphere model: read from the cache, else from the package's (:data:`SHIPPED`), when it was
    made for these geometries and mesh files; else fitted (panda 3.6 s of CPU, centauro 17.3 s: docs/benchmarks.md)
    and cached."""
    stamp = cache_stamp(robot)
    path = cache_path(robot, stamp)
    geometries = len(robot.collision_model.geometryObjects)
    for made in (path, SHIPPED / path.name):
        cached = read_cache(made, stamp, geometries)
        if cached is not None:
            return cached
    with progress_bar(f"sphere models of {robot.name} (once, then cached)", geometries,
                      enabled=sys.stderr.isatty()) as bar:  # a bar on a terminal only: no log fills with it
        model = fit_model(robot.collision_model, fitted=bar.advance)
    arrays = {k: getattr(model, k) for k in ("joint", "center", "radius", "geometry", "solid_volume",
                                             "union_volume")}
    arrays["unfitted"] = np.array(model.unfitted, int)
    try:
        save_npz(path, {"robot": robot.name, **stamp, "arrays_sha256": _arrays_digest(arrays),
                        "reasons": list(model.reasons)}, **arrays)
    except ManifoldgenError as exc:  # an unwritable cache costs time, not correctness
        warnings.warn(f"sphere model not cached: {exc}")
    return model


def cache_path(robot: Robot, stamp: dict) -> Path:
    """The file the robot's sphere model made for ``stamp`` (:func:`cache_stamp`) is cached in."""
    return cache_dir() / "spheres" / f"{robot.name}-{_digest(stamp)[:16]}.npz"


def cache_stamp(robot: Robot) -> dict:
    """What a cached model must have been made for: this code's settings and the robot's geometries."""
    return {"version": VERSION, "slack": VOLUME_SLACK, "shell": SHELL_SLACK, "grid": VOLUME_GRID,
            "counts": [list(c) for c in COLUMN_COUNTS], "prism": PRISM_SIDES,
            "geometries_sha256": _geometry_digest(robot.collision_model)}


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
