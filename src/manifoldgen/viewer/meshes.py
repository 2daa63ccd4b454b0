"""Triangle meshes of a robot, its scene's obstacles and the held tool, placed by pinocchio.

A :class:`Part` is a rigid mesh fixed to a pinocchio joint (joint 0: the world). The robot is
drawn from the ``<visual>`` elements of its URDF, read here directly (binary STL files with
numpy, other mesh formats through coal), which is several times faster than building pinocchio's
visual model; when they cannot be read, from its collision geometry, and the note says so.
Meshes of more than ``SIMPLIFY_ABOVE`` triangles are simplified by merging the vertices in each
``MESH_CELL`` cube (vertex clustering): panda's 135k triangles become 39k and centauro's 381k
become 159k: less for a browser without a GPU to draw.
:func:`part_poses` places every part for a batch of configurations.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin

from manifoldgen.robot import Robot, robots_dir
from manifoldgen.scene import Scene
from manifoldgen.shapes import Obstacle

ROBOT_COLOR = np.array([0.75, 0.75, 0.78, 1.0])  # a visual element without a material
COLLISION_COLOR = np.array([0.8, 0.6, 0.3, 1.0])
OBSTACLE_COLOR = np.array([0.55, 0.57, 0.62, 0.55])
TOOL_COLOR = np.array([0.85, 0.15, 0.15, 1.0])
MESH_CELL = 0.006  # m
SIMPLIFY_ABOVE = 1000  # triangles
STL_RECORD = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])


@dataclass
class Part:
    """A rigid mesh: ``vertices (V, 3)`` and ``faces (F, 3)`` in its own frame, placed by
    ``placement (4, 4)`` in the frame of pinocchio ``joint``; ``color (4,)`` RGBA in [0, 1]."""

    name: str
    joint: int
    placement: np.ndarray
    vertices: np.ndarray
    faces: np.ndarray
    color: np.ndarray


def robot_parts(robot: Robot, visual: bool = True) -> tuple[list[Part], str]:
    """The robot's parts and a note ('' or why collision geometry is drawn instead of visual meshes)."""
    note = ""
    if visual:
        try:
            parts = _visual_parts(robot)
            if parts:
                return parts, ""
            note = f"the URDF of {robot.name} has no visual elements: drawing its collision geometry"
        except (OSError, ValueError, RuntimeError, ET.ParseError) as exc:
            note = f"visual meshes of {robot.name} cannot be loaded ({exc}): drawing its collision geometry instead"
    parts = [Part(o.name, o.parentJoint, o.placement.homogeneous, *shape_mesh(o.geometry), COLLISION_COLOR)
             for o in robot.collision_model.geometryObjects]
    return parts, note


def scene_parts(scene: Scene, robot: Robot) -> list[Part]:
    """Obstacles (fixed in the world) and the held tool (fixed to its frame's joint, named ``held_<name>``)."""
    parts = [_obstacle_part(o, 0, o.pose.se3().homogeneous, OBSTACLE_COLOR) for o in scene.obstacles]
    if scene.attached is not None:
        frame = robot.model.frames[robot.frame_id(scene.attached.frame)]
        placement = (frame.placement * scene.attached.shape.pose.se3()).homogeneous
        tool = _obstacle_part(scene.attached.shape, frame.parentJoint, placement, TOOL_COLOR)
        tool.name = f"held_{tool.name}"
        parts.append(tool)
    return parts


def _obstacle_part(obstacle: Obstacle, joint: int, placement: np.ndarray, color: np.ndarray) -> Part:
    return Part(obstacle.name, joint, placement, *shape_mesh(obstacle.geometry()), color)


def _visual_parts(robot: Robot) -> list[Part]:
    """One part per ``<visual>`` of each URDF link that the pinocchio model has as a body frame."""
    urdf = Path(robot.urdf_path)
    root = ET.parse(urdf).getroot()
    materials = {m.get("name"): _rgba(m) for m in root.iter("material") if m.find("color") is not None}
    parts = []
    for link in root.iter("link"):
        name = link.get("name")
        if not robot.model.existFrame(name, pin.FrameType.BODY):
            continue
        frame = robot.model.frames[robot.model.getFrameId(name, pin.FrameType.BODY)]
        for k, element in enumerate(link.findall("visual")):
            vertices, faces = _urdf_geometry(element.find("geometry"), urdf)
            material = element.find("material")
            color = ROBOT_COLOR if material is None else (
                _rgba(material) if material.find("color") is not None else materials.get(material.get("name"),
                                                                                          ROBOT_COLOR))
            if len(faces) > SIMPLIFY_ABOVE:
                vertices, faces = simplify(vertices, faces, MESH_CELL)
            placement = frame.placement.homogeneous @ _origin(element.find("origin"))
            parts.append(Part(f"{name}_{k}", frame.parentJoint, placement, vertices, faces, color))
    return parts


def _urdf_geometry(geometry, urdf: Path) -> tuple[np.ndarray, np.ndarray]:
    shape = geometry[0] if geometry is not None and len(geometry) else None
    if shape is None:
        raise ValueError(f"{urdf.name}: a <visual> without <geometry>")
    if shape.tag == "mesh":
        scale = _floats(shape.get("scale", "1 1 1"))
        return _mesh_file(_resolve(shape.get("filename", ""), urdf), scale)
    if shape.tag == "box":
        return box_mesh(_floats(shape.get("size")))
    if shape.tag == "cylinder":
        return cylinder_mesh(float(shape.get("radius")), float(shape.get("length")))
    if shape.tag == "sphere":
        return sphere_mesh(float(shape.get("radius")))
    raise ValueError(f"{urdf.name}: unknown visual geometry <{shape.tag}>")


def _resolve(filename: str, urdf: Path) -> Path:
    """A URDF mesh reference (``package://pkg/...``, ``file://...`` or a path relative to the URDF)."""
    if filename.startswith("package://"):
        relative = filename.removeprefix("package://")
        for root in (robots_dir().parent.parent, urdf.parent.parent, urdf.parent):
            if (root / relative).is_file():
                return root / relative
        raise FileNotFoundError(f"mesh {filename} not found")
    path = Path(filename.removeprefix("file://"))
    path = path if path.is_absolute() else urdf.parent / path
    if not path.is_file():
        raise FileNotFoundError(f"mesh {filename} not found")
    return path


def _mesh_file(path: Path, scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A binary STL read with numpy (shared vertices merged), any other format through coal."""
    data = path.read_bytes() if path.suffix.lower() == ".stl" else b""
    count = int.from_bytes(data[80:84], "little") if len(data) >= 84 else -1
    if len(data) != 84 + STL_RECORD.itemsize * count:
        return shape_mesh(coal.MeshLoader().load(str(path), np.asarray(scale, float)))
    corners = np.ascontiguousarray(np.frombuffer(data, STL_RECORD, count, 84)["vertices"].reshape(-1, 3))
    _, first, faces = np.unique(corners.view(np.dtype((np.void, 12))).ravel(), return_index=True,
                                return_inverse=True)
    return (corners[first] * scale).astype(np.float32), faces.reshape(-1, 3).astype(np.int32)


def simplify(vertices: np.ndarray, faces: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertex clustering: the vertices in each ``cell``-sized cube merged into their mean; the
    triangles that collapse are dropped."""
    key = np.ascontiguousarray(np.floor((vertices - vertices.min(0)) / cell).astype(np.int64))
    _, cluster = np.unique(key.view(np.dtype((np.void, 24))).ravel(), return_inverse=True)
    count = np.bincount(cluster)
    merged = np.zeros((len(count), 3))
    np.add.at(merged, cluster, vertices)
    faces = cluster[faces]
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    return (merged / count[:, None]).astype(np.float32), faces[keep].astype(np.int32)


def shape_mesh(geometry) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) float32 vertices and (F, 3) int32 faces of a coal shape (meshes as coal loaded them, scaled)."""
    if isinstance(geometry, coal.Box):
        return box_mesh(2 * np.asarray(geometry.halfSide))
    if isinstance(geometry, coal.Sphere):
        return sphere_mesh(geometry.radius)
    if isinstance(geometry, coal.Cylinder):
        return cylinder_mesh(geometry.radius, 2 * geometry.halfLength)
    if isinstance(geometry, coal.Capsule):
        return sphere_mesh(geometry.radius, 2 * geometry.halfLength)
    if isinstance(geometry, coal.BVHModelBase):
        faces = np.array([[t[0], t[1], t[2]] for t in map(geometry.tri_indices, range(geometry.num_tris))])
        return geometry.vertices().astype(np.float32), faces.reshape(-1, 3).astype(np.int32)
    if isinstance(geometry, coal.ConvexBase):
        from scipy.spatial import ConvexHull
        points = np.asarray(geometry.points())
        return points.astype(np.float32), ConvexHull(points).simplices.astype(np.int32)
    raise ValueError(f"cannot draw a {type(geometry).__name__}")


def box_mesh(size) -> tuple[np.ndarray, np.ndarray]:
    """A box of full extents ``size (3,)`` centred on the origin."""
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]) * size
    faces = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
             [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    return corners.astype(np.float32), np.array(faces, np.int32)


def sphere_mesh(radius: float, length: float = 0.0, rings: int = 12,
                sectors: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """A UV sphere; with ``length`` > 0 a capsule along z (its hemispheres that far apart)."""
    theta = np.linspace(0, np.pi, rings + 1)[:, None]
    phi = np.linspace(0, 2 * np.pi, sectors, endpoint=False)[None]
    points = radius * np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                                np.cos(theta) * np.ones_like(phi)], axis=-1).reshape(-1, 3)
    points[:, 2] += np.where(np.repeat(np.arange(rings + 1), sectors) <= rings // 2, length / 2, -length / 2)
    faces = []
    for i in range(rings):
        for j in range(sectors):
            a, b = i * sectors + j, i * sectors + (j + 1) % sectors
            faces += [[a, a + sectors, b], [b, a + sectors, b + sectors]]
    return points.astype(np.float32), np.array(faces, np.int32)


def cylinder_mesh(radius: float, length: float, sectors: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """A cylinder along z centred on the origin."""
    phi = np.linspace(0, 2 * np.pi, sectors, endpoint=False)
    ring = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.zeros(sectors)], axis=1)
    points = np.concatenate([ring - [0, 0, length / 2], ring + [0, 0, length / 2], [[0, 0, -length / 2]],
                             [[0, 0, length / 2]]])
    faces = []
    for j in range(sectors):
        k = (j + 1) % sectors
        faces += [[j, k, sectors + k], [j, sectors + k, sectors + j], [2 * sectors, k, j],
                  [2 * sectors + 1, sectors + j, sectors + k]]
    return points.astype(np.float32), np.array(faces, np.int32)


def _origin(element) -> np.ndarray:
    """(4, 4) transform of a URDF ``<origin xyz rpy>`` (identity when absent)."""
    T = np.eye(4)
    if element is not None:
        T[:3, :3] = pin.rpy.rpyToMatrix(*_floats(element.get("rpy", "0 0 0")))
        T[:3, 3] = _floats(element.get("xyz", "0 0 0"))
    return T


def _rgba(material) -> np.ndarray:
    return _floats(material.find("color").get("rgba", "0.75 0.75 0.78 1"))


def _floats(text: str | None) -> np.ndarray:
    return np.array([float(v) for v in (text or "").split()])


def joint_poses(robot: Robot, q: np.ndarray, joints: list[int]) -> np.ndarray:
    """(B, J, 4, 4) world poses of pinocchio ``joints`` (0: the world) for ``q (B, n)``."""
    full = robot.to_pinocchio(q)
    data = robot.model.createData()
    out = np.empty((len(full), len(joints), 4, 4))
    for b, row in enumerate(full):
        pin.forwardKinematics(robot.model, data, row)
        for j, joint in enumerate(joints):
            out[b, j] = data.oMi[joint].homogeneous
    return out


def part_poses(robot: Robot, parts: list[Part], q: np.ndarray) -> np.ndarray:
    """(B, P, 4, 4) world poses of ``parts`` for configurations ``q (B, n)``."""
    joints = sorted({p.joint for p in parts})
    poses = joint_poses(robot, q, joints)
    index = [joints.index(p.joint) for p in parts]
    return poses[:, index] @ np.stack([p.placement for p in parts])
