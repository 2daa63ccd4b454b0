"""Conservative sphere models of a robot's collision geometries: fitted (:mod:`.fit`), kept on disk (:mod:`.cache`)
and checked in batches (:mod:`.checker`)."""

from manifoldgen.spheres.cache import cache_path, cache_stamp, read_cache, sphere_model
from manifoldgen.spheres.checker import SphereChecker
from manifoldgen.spheres.fit import SphereModel, fit_geometry, fit_model, fit_or_reason, solid_volume, triangles_of

__all__ = ["SphereChecker", "SphereModel", "cache_path", "cache_stamp", "fit_geometry", "fit_model", "fit_or_reason", "read_cache",
           "solid_volume", "sphere_model", "triangles_of"]
