"""Collision shapes: an obstacle placed in the world (box, sphere, cylinder or mesh), a tool the robot holds, and
the collision checker of a robot with both (:func:`held_checker`).

An obstacle is placed by a pose (position + quaternion ``[x, y, z, w]``) in the world; a held tool by a pose in
a robot frame. Both read from and write to the JSON objects of scene files, task files' ``[attached]`` tables
and path files' meta.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin

from manifoldgen.collision import CollisionChecker, touch_links
from manifoldgen.errors import ManifoldgenError, check_keys
from manifoldgen.robot import Robot

OBSTACLE_TYPES = ("box", "sphere", "cylinder", "mesh")
OBSTACLE_KEYS = ("name", "type", "pose", "size", "radius", "length", "mesh", "scale")
SHAPE_KEYS = {"box": ("size",), "sphere": ("radius",), "cylinder": ("radius", "length"), "mesh": ("mesh", "scale")}
HELD_KEYS = ("attached_to", "touch_links", "parent_joint")  # a held object's keys beside its shape's
MAX_METRES = 1e3  # largest position coordinate or extent accepted (coal's bounding boxes overflow near 1e308)


def _bounded(values: np.ndarray, what: str) -> np.ndarray:
    if np.any(np.abs(values) > MAX_METRES):
        raise ManifoldgenError(f"{what} {values.tolist()} is beyond {MAX_METRES:g} m; give metres within that")
    return values


def _vector(value, size: int, what: str) -> np.ndarray:
    for item in np.ravel(np.asarray(value, dtype=object)):
        if isinstance(item, (bool, np.bool_, str)):
            kind = "a string" if isinstance(item, str) else "true/false"
            raise ManifoldgenError(f"{what} must be {size} numbers, not {kind} ({item!r}), got {value!r}")
    try:
        out = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ManifoldgenError(f"{what} must be {size} numbers, got {value!r}") from exc
    if out.shape != (size,) or not np.all(np.isfinite(out)):  # a flat list: [[0.5]] is not one number
        raise ManifoldgenError(f"{what} must be {size} finite numbers, got {value!r}")
    return out


def float_list(value, what: str) -> np.ndarray:
    """``value`` as a flat array when it is a non-empty list of finite numbers, else a clear error."""
    if not isinstance(value, list) or not value:
        raise ManifoldgenError(f"{what} must be a non-empty list of numbers, got {value!r}")
    return _vector(value, len(value), what)


def _positive(value, what: str) -> float:
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not np.isfinite(value) or value <= 0:
        raise ManifoldgenError(f"{what} must be a positive number of metres, got {value!r}")
    return float(_bounded(np.array([value], float), what)[0])


@dataclass(frozen=True)
class Pose:
    """A rigid placement: position (3,) in metres and unit quaternion (4,) ``[x, y, z, w]``."""

    position: np.ndarray
    quaternion: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))

    def __post_init__(self):
        object.__setattr__(self, "position", _bounded(_vector(self.position, 3, "pose position"), "pose position"))
        quat = _vector(self.quaternion, 4, "pose quaternion [x, y, z, w]")
        norm = np.linalg.norm(quat)
        if abs(norm - 1.0) > 1e-3:
            raise ManifoldgenError(f"pose quaternion {quat.tolist()} has norm {norm:.4f}; give a unit "
                                   "quaternion [x, y, z, w]")
        object.__setattr__(self, "quaternion", quat / norm)

    def se3(self) -> pin.SE3:
        x, y, z, w = self.quaternion
        return pin.SE3(pin.Quaternion(w, x, y, z).toRotationMatrix(), self.position.copy())

    def to_dict(self) -> dict:
        return {"position": self.position.tolist(), "quaternion": self.quaternion.tolist()}

    @classmethod
    def from_dict(cls, data, what: str) -> Pose:
        if not isinstance(data, dict) or "position" not in data:
            raise ManifoldgenError(f"{what}: pose needs 'position' [x, y, z] (and 'quaternion' [x, y, z, w])")
        check_keys(data, ("position", "quaternion"), f"{what} pose")
        return cls(_vector(data["position"], 3, f"{what} pose position"),
                   _vector(data.get("quaternion", [0.0, 0.0, 0.0, 1.0]), 4, f"{what} pose quaternion [x, y, z, w]"))


@dataclass
class Obstacle:
    """One collision shape; ``size`` = full extents (box), ``radius`` (sphere, cylinder),
    ``length`` (cylinder, along its z), ``mesh`` file and ``scale`` (mesh)."""

    name: str
    type: str
    pose: Pose
    size: np.ndarray | None = None
    radius: float | None = None
    length: float | None = None
    mesh: str | None = None
    scale: np.ndarray | None = None

    def __post_init__(self):
        what = f"obstacle '{self.name}'"
        if self.type not in OBSTACLE_TYPES:
            close = difflib.get_close_matches(str(self.type), OBSTACLE_TYPES, n=1)
            hint = f" (did you mean {close[0]}?)" if close else ""
            raise ManifoldgenError(f"{what} has unknown type '{self.type}'{hint}; known types: "
                                   f"{', '.join(OBSTACLE_TYPES)}")
        if self.type == "box":
            self.size = _bounded(_vector(self.size, 3, f"{what} size (full extents x, y, z)"), f"{what} size")
            if np.any(self.size <= 0):
                raise ManifoldgenError(f"{what} size {self.size.tolist()} must be three positive extents in metres")
        if self.type in ("sphere", "cylinder"):
            self.radius = _positive(self.radius, f"{what} radius")
        if self.type == "cylinder":
            self.length = _positive(self.length, f"{what} length")
        if self.type == "mesh":
            if not isinstance(self.mesh, str) or not self.mesh or not Path(self.mesh).is_file():
                why = "is not a regular file" if isinstance(self.mesh, str) and self.mesh and Path(
                    self.mesh).exists() else "not found"
                raise ManifoldgenError(f"{what}: mesh file {self.mesh!r} {why}; give the path of an "
                                       ".stl, .obj or .dae file")
            scale = 1.0 if self.scale is None else self.scale
            self.scale = _vector(np.broadcast_to(scale, 3) if np.ndim(scale) == 0 else scale, 3, f"{what} scale")
            if np.any(self.scale <= 0):
                raise ManifoldgenError(f"{what} scale {self.scale.tolist()} must be positive")
            _bounded(self.scale, f"{what} scale")
            self.geometry()  # an unreadable or malformed mesh fails here, with its reason

    def geometry(self) -> coal.CollisionGeometry:
        if self.type == "box":
            return coal.Box(*self.size)
        if self.type == "sphere":
            return coal.Sphere(self.radius)
        if self.type == "cylinder":
            return coal.Cylinder(self.radius, self.length)
        try:
            mesh = coal.MeshLoader().load(str(self.mesh), self.scale)
        except Exception as exc:  # coal raises ValueError with assimp's report for bad files
            lines = [line for line in str(exc).splitlines() if line and not line.startswith(("From file", "in function",
                                                                                         "at line", "Hint"))]
            why = " ".join(lines).replace("message: ", "")[:160] or type(exc).__name__
            raise ManifoldgenError(f"obstacle '{self.name}': cannot read mesh file {self.mesh} ({why}); give a "
                                   "readable .stl, .obj or .dae file") from None
        if mesh.num_vertices == 0:
            raise ManifoldgenError(f"obstacle '{self.name}': mesh file {self.mesh} has no vertices")
        return mesh

    def geometry_object(self, joint: int = 0, frame: int = 0, placement: pin.SE3 | None = None) -> pin.GeometryObject:
        """The pinocchio object; by default fixed in the world (joint 0) at ``pose``."""
        placement = self.pose.se3() if placement is None else placement
        return pin.GeometryObject(self.name, joint, frame, placement, self.geometry())

    def local_points(self) -> np.ndarray:
        """(P, 3) points whose convex hull is the shape, in its own frame (for drawing)."""
        if self.type == "box":
            corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
            return corners * self.size / 2
        angles = np.linspace(0, 2 * np.pi, 24, endpoint=False)
        ring = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
        if self.type == "sphere":
            return self.radius * np.concatenate([ring, ring[:, [0, 2, 1]], ring[:, [2, 0, 1]]])
        if self.type == "cylinder":
            return np.concatenate([self.radius * ring + [0, 0, s * self.length / 2] for s in (-1, 1)])
        shape = self.geometry()
        return np.array([shape.vertices(i) for i in range(shape.num_vertices)])

    def to_dict(self) -> dict:
        out = {"name": self.name, "type": self.type, "pose": self.pose.to_dict()}
        if self.type == "box":
            out["size"] = self.size.tolist()
        if self.type in ("sphere", "cylinder"):
            out["radius"] = self.radius
        if self.type == "cylinder":
            out["length"] = self.length
        if self.type == "mesh":
            out["mesh"] = str(Path(self.mesh).resolve())
            out["scale"] = self.scale.tolist()
        return out

    @classmethod
    def from_dict(cls, data, index: int = 0) -> Obstacle:
        if not isinstance(data, dict):
            raise ManifoldgenError(f"obstacle {index} must be a JSON object with 'type' and 'pose'")
        name = str(data.get("name", f"obstacle{index}"))
        check_keys(data, OBSTACLE_KEYS, f"obstacle '{name}'")
        if "type" not in data:
            raise ManifoldgenError(f"obstacle '{name}' has no 'type'; known types: {', '.join(OBSTACLE_TYPES)}")
        obstacle = cls(name, data["type"], Pose.from_dict(data.get("pose"), f"obstacle '{name}'"),
                       size=data.get("size"), radius=data.get("radius"), length=data.get("length"),
                       mesh=data.get("mesh"), scale=data.get("scale"))
        check_keys(data, ("name", "type", "pose", *SHAPE_KEYS[obstacle.type]), f"obstacle '{name}' (a {obstacle.type})")
        return obstacle


@dataclass
class Attached:
    """A tool held by the robot: ``shape`` placed by ``shape.pose`` relative to ``frame``;
    it may touch ``touch_links`` (the hand and fingers), nothing else."""

    shape: Obstacle
    frame: str
    touch_links: list[str] | None = None

    def geometry_object(self, robot: Robot) -> pin.GeometryObject:
        frame = robot.model.frames[robot.frame_id(self.frame)]
        return self.shape.geometry_object(frame.parentJoint, robot.frame_id(self.frame),
                                          frame.placement * self.shape.pose.se3())

    def resolved_touch_links(self, robot: Robot) -> list[str]:
        if self.touch_links is not None:
            links = {robot.model.frames[g.parentFrame].name for g in robot.collision_model.geometryObjects}
            unknown = sorted(set(self.touch_links) - links)
            if unknown:
                raise ManifoldgenError(f"attached tool touch links {unknown} are not links of robot "
                                       f"{robot.name}; known: {', '.join(sorted(links))}")
            return list(self.touch_links)
        return touch_links(robot, robot.model.frames[robot.frame_id(self.frame)].parentJoint)

    def to_dict(self) -> dict:
        out = self.shape.to_dict()
        out["attached_to"] = self.frame
        if self.touch_links is not None:
            out["touch_links"] = list(self.touch_links)
        return out

    @classmethod
    def from_dict(cls, data) -> Attached:
        if isinstance(data, dict):
            check_keys(data, OBSTACLE_KEYS + HELD_KEYS, "attached")
        if not isinstance(data, dict) or "attached_to" not in data:
            raise ManifoldgenError("the attached tool needs 'attached_to' (a robot frame), 'type' and 'pose' "
                                   "(its placement in that frame)")
        shape = Obstacle.from_dict({k: v for k, v in data.items() if k not in HELD_KEYS})
        links = data.get("touch_links")
        return cls(shape, str(data["attached_to"]), None if links is None else [str(x) for x in links])


def held_checker(robot: Robot, held: Attached | None, obstacles: list[pin.GeometryObject] | None = None,
                 ) -> CollisionChecker:
    """Self-collision, ``obstacles`` and the ``held`` object (None: nothing held) for ``robot``."""
    if held is None:
        return CollisionChecker(robot, obstacles=obstacles)
    return CollisionChecker(robot, obstacles=obstacles, attached=[held.geometry_object(robot)],
                            touch=[held.resolved_touch_links(robot)])
