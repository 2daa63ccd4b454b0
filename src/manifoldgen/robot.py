"""Robot models: planning groups, joint limits, batched kinematics.

Pinocchio loads the URDF (+ SRDF) and owns the full model; this module builds, once,
a vectorised description of the tree restricted to a planning group (active joints),
so that forward kinematics, frame Jacobians and the centre of mass run on whole
batches ``q (B, n)`` in numpy. A floating base is six Euclidean coordinates
``(x, y, z, yaw, pitch, roll)`` (ZYX Euler), mapped to pinocchio's free flyer.
"""

from __future__ import annotations

import difflib
import os
import site
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import pinocchio as pin

from manifoldgen.errors import ManifoldgenError

BASE_JOINTS = ("base_x", "base_y", "base_z", "base_yaw", "base_pitch", "base_roll")
_BASE_AXES = (("P", (1, 0, 0)), ("P", (0, 1, 0)), ("P", (0, 0, 1)),
              ("R", (0, 0, 1)), ("R", (0, 1, 0)), ("R", (1, 0, 0)))
# example-robot-data names whose files do not follow <name>_description/{urdf,srdf}/<name>.*
_SPECIAL_FILES = {"baxter": ("baxter", "baxter_manipulation")}


def robots_dir() -> Path:
    """Folder of example-robot-data's robots (the package ships no Python module)."""
    for root in [*site.getsitepackages(), site.getusersitepackages()]:
        path = Path(root) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
        if path.is_dir():
            return path
    raise ManifoldgenError("example-robot-data is not installed: run `pip install example-robot-data`")


def known_robots() -> list[str]:
    """Names of example-robot-data robots that have a URDF at the conventional place."""
    names = []
    for folder in sorted(robots_dir().glob("*_description")):
        name = folder.name.removesuffix("_description")
        if _robot_files(name)[0].exists():
            names.append(name)
    return names


def _robot_files(name: str) -> tuple[Path, Path]:
    urdf_stem, srdf_stem = _SPECIAL_FILES.get(name, (name, name))
    folder = robots_dir() / f"{name}_description"
    return folder / "urdf" / f"{urdf_stem}.urdf", folder / "srdf" / f"{srdf_stem}.srdf"


def resolve_robot(robot: str) -> tuple[Path, Path | None]:
    """Map an example-robot-data name or a URDF path to ``(urdf, srdf or None)``."""
    if robot.endswith(".urdf") or os.sep in robot:
        urdf = Path(robot)
        if not urdf.is_file():
            raise ManifoldgenError(f"URDF file not found: {robot}; give an existing path or a robot name")
        srdf = urdf.with_suffix(".srdf")
        return urdf, srdf if srdf.is_file() else None
    urdf, srdf = _robot_files(robot)
    if not urdf.exists():
        close = difflib.get_close_matches(robot, known_robots(), n=3)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise ManifoldgenError(
            f"unknown robot '{robot}'{hint}; known: {', '.join(known_robots())}, or a path to a .urdf")
    return urdf, srdf if srdf.exists() else None


@dataclass(frozen=True)
class _Motion:
    """One elementary joint motion: rotation about or translation along a local axis."""

    kind: str  # "R" or "P"
    axis: np.ndarray  # (3,) unit axis in the joint frame
    index: int  # column in q


@dataclass(frozen=True)
class _Link:
    """A joint of the full model seen from the planning group."""

    parent: int  # full-model joint id of the parent (0 = universe)
    placement: np.ndarray  # (4, 4) parent joint frame -> this joint, before motion
    motions: tuple[_Motion, ...]  # empty for a locked joint (its motion is in placement)


class Robot:
    """A robot model with a planning group of active joints; the others are locked.

    Build with :meth:`Robot.load`. ``q`` arrays are ``(B, n)`` float64 in the order of
    ``joints``; single configurations ``(n,)`` are accepted and promoted.
    """

    def __init__(self, name: str, model: pin.Model, collision_model: pin.GeometryModel,
                 srdf: Path | None, joints: list[str], reference: np.ndarray,
                 floating_base: bool, base_bounds: np.ndarray):
        self.name = name
        self.model = model
        self.collision_model = collision_model
        self.srdf = srdf
        self.joints = list(joints)
        self.reference = reference  # (model.nq,) full pinocchio configuration for locked joints
        self.floating_base = floating_base
        self._joint_ids = [model.getJointId(j) for j in joints if j not in BASE_JOINTS]
        self.lower, self.upper = self._limits(base_bounds)
        self._links = self._build_links()

    # ------------------------------------------------------------------ construction
    @classmethod
    def load(cls, robot: str, joints: list[str] | None = None, *,
             reference: dict[str, float] | None = None, floating_base: bool = False,
             base_bounds: tuple[tuple[float, ...], tuple[float, ...]] = ((-2, -2, -1), (2, 2, 2))) -> Robot:
        """Load an example-robot-data name or a URDF path (an SRDF beside it is used).

        joints: the planning group, in order (default: every movable joint).
        reference: values of locked joints (default: the SRDF's first group state, else neutral).
        floating_base: prepend the six coordinates of ``BASE_JOINTS``, bounded by
        ``base_bounds`` (translation low, high; angles are bounded by ±pi).
        """
        urdf, srdf = resolve_robot(robot)
        share = str(robots_dir().parent.parent)
        try:
            model = (pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer()) if floating_base
                     else pin.buildModelFromUrdf(str(urdf)))
            collision = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.COLLISION,
                                              package_dirs=[share, str(urdf.parent.parent)])
        except (RuntimeError, ValueError) as exc:
            raise ManifoldgenError(f"cannot parse URDF {urdf}: {str(exc).splitlines()[0]}; "
                                   "check that the file is a valid URDF") from exc
        movable = [model.names[j] for j in range(1, model.njoints)
                   if model.joints[j].nq > 0 and model.names[j] != "root_joint"]
        base = list(BASE_JOINTS) if floating_base else []
        joints = base + (movable if joints is None else [j for j in joints if j not in BASE_JOINTS])
        for j in joints:
            if j not in BASE_JOINTS and j not in movable:
                close = difflib.get_close_matches(j, movable, n=3)
                hint = f"did you mean {', '.join(close)}?" if close else f"movable joints: {', '.join(movable)}"
                raise ManifoldgenError(f"unknown joint '{j}' for robot {robot}; {hint}")
        q_ref = pin.neutral(model)
        if srdf is not None:
            states = _srdf_states(srdf)
            for name, value in (states[0][1].items() if states else []):
                _set_joint(model, q_ref, name, value)
        for name, value in (reference or {}).items():
            if not model.existJointName(name):
                raise ManifoldgenError(f"unknown joint '{name}' in reference for robot {robot}")
            _set_joint(model, q_ref, name, value)
        return cls(robot, model, collision, srdf, joints, q_ref, floating_base,
                   np.asarray(base_bounds, dtype=float))

    def _limits(self, base_bounds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lower, upper = [], []
        if self.floating_base:
            lower += [*base_bounds[0], -np.pi, -np.pi / 2, -np.pi]
            upper += [*base_bounds[1], np.pi, np.pi / 2, np.pi]
        for jid in self._joint_ids:
            jm = self.model.joints[jid]
            if jm.nq == 2:  # continuous joint: the angle is bounded to one turn
                lower.append(-np.pi)
                upper.append(np.pi)
            else:
                lo, hi = self.model.lowerPositionLimit[jm.idx_q], self.model.upperPositionLimit[jm.idx_q]
                lower.append(max(lo, -np.pi) if lo < -1e10 else lo)
                upper.append(min(hi, np.pi) if hi > 1e10 else hi)
        return np.array(lower), np.array(upper)

    def _build_links(self) -> dict[int, _Link]:
        model, data = self.model, self.model.createData()
        pin.forwardKinematics(model, data, self.reference)
        col = {jid: i + (6 if self.floating_base else 0) for i, jid in enumerate(self._joint_ids)}
        links = {}
        for jid in range(1, model.njoints):
            jm = model.joints[jid]
            placement = model.jointPlacements[jid].homogeneous
            if self.floating_base and jid == 1:
                motions = tuple(_Motion(k, np.array(a, float), i) for i, (k, a) in enumerate(_BASE_AXES))
            elif jid in col:
                kind, axis = _joint_axis(jm)
                motions = (_Motion(kind, axis, col[jid]),)
            else:
                placement, motions = data.liMi[jid].homogeneous, ()
            links[jid] = _Link(model.parents[jid], placement, motions)
        return links

    # ------------------------------------------------------------------ basic facts
    @property
    def n(self) -> int:
        """Number of active coordinates."""
        return len(self.joints)

    @cached_property
    def locked(self) -> dict[str, float]:
        """Locked joint name -> reference value (for one-coordinate joints)."""
        out = {}
        for jid in range(1, self.model.njoints):
            name, jm = self.model.names[jid], self.model.joints[jid]
            if jid in self._joint_ids or (self.floating_base and jid == 1) or jm.nq == 0:
                continue
            q = self.reference[jm.idx_q:jm.idx_q + jm.nq]
            out[name] = float(np.arctan2(q[1], q[0])) if jm.nq == 2 else float(q[0])
        return out

    def frame_id(self, frame: str) -> int:
        """Pinocchio frame id, with a clear error for an unknown frame."""
        if not self.model.existFrame(frame):
            names = [f.name for f in self.model.frames]
            close = difflib.get_close_matches(frame, names, n=3)
            raise ManifoldgenError(f"unknown frame '{frame}' for robot {self.name}; "
                                   f"did you mean {', '.join(close) or 'one of its links'}?")
        return self.model.getFrameId(frame)

    def within_limits(self, q: np.ndarray, margin: float = 1e-9) -> np.ndarray:
        """(B,) bool: every coordinate inside its limits."""
        q = as_batch(q, self.n)
        return np.all((q >= self.lower - margin) & (q <= self.upper + margin), axis=1)

    def sample_uniform(self, count: int, rng: np.random.Generator) -> np.ndarray:
        """(count, n) configurations uniform inside the joint limits."""
        return rng.uniform(self.lower, self.upper, size=(count, self.n))

    def to_pinocchio(self, q: np.ndarray) -> np.ndarray:
        """(B, n) -> (B, model.nq) full pinocchio configurations (locked joints at reference)."""
        q = as_batch(q, self.n)
        full = np.repeat(self.reference[None], len(q), axis=0)
        offset = 0
        if self.floating_base:
            full[:, :3] = q[:, :3]
            full[:, 3:7] = _zyx_quaternion(q[:, 3], q[:, 4], q[:, 5])
            offset = 6
        for i, jid in enumerate(self._joint_ids):
            jm, angle = self.model.joints[jid], q[:, offset + i]
            if jm.nq == 2:
                full[:, jm.idx_q], full[:, jm.idx_q + 1] = np.cos(angle), np.sin(angle)
            else:
                full[:, jm.idx_q] = angle
        return full

    # ------------------------------------------------------------------ kinematics
    def _ancestors(self, jid: int) -> list[int]:
        chain = []
        while jid > 0:
            chain.append(jid)
            jid = self._links[jid].parent
        return chain[::-1]

    def _world(self, q: np.ndarray, joint_ids: list[int], axes: bool = False):
        """World transforms (B, 4, 4) of the given joints (and their ancestors).

        With axes=True also returns, per active coordinate met, (world axis (B,3), world
        origin (B,3), kind) as a dict keyed by column.
        """
        needed = sorted({a for j in joint_ids for a in self._ancestors(j)})
        world = {0: np.broadcast_to(np.eye(4), (len(q), 4, 4))}
        met = {}
        for jid in needed:
            link = self._links[jid]
            T = world[link.parent] @ link.placement
            for m in link.motions:
                if axes:
                    met[m.index] = (T[:, :3, :3] @ m.axis, T[:, :3, 3].copy(), m.kind)
                T = T @ _motion(m, q[:, m.index])
            world[jid] = T
        return (world, met) if axes else world

    def frame_pose(self, q: np.ndarray, frame: str) -> tuple[np.ndarray, np.ndarray]:
        """World position (B, 3) and rotation (B, 3, 3) of ``frame``."""
        q = as_batch(q, self.n)
        f = self.model.frames[self.frame_id(frame)]
        T = self._world(q, [f.parentJoint])[f.parentJoint] @ f.placement.homogeneous
        return T[:, :3, 3], T[:, :3, :3]

    def frame_jacobian(self, q: np.ndarray, frame: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position (B, 3), rotation (B, 3, 3) and world-aligned Jacobian (B, 6, n) of ``frame``.

        Rows 0-2: linear velocity of the frame origin, rows 3-5: angular velocity, both in
        world axes (pinocchio's LOCAL_WORLD_ALIGNED).
        """
        q = as_batch(q, self.n)
        f = self.model.frames[self.frame_id(frame)]
        world, met = self._world(q, [f.parentJoint], axes=True)
        T = world[f.parentJoint] @ f.placement.homogeneous
        return T[:, :3, 3], T[:, :3, :3], self._point_jacobian(T[:, :3, 3], met, len(q), angular=True)

    def _point_jacobian(self, point: np.ndarray, met: dict, batch: int, angular: bool) -> np.ndarray:
        J = np.zeros((batch, 6 if angular else 3, self.n))
        for col, (axis, origin, kind) in met.items():
            if kind == "R":
                J[:, :3, col] = np.cross(axis, point - origin)
                if angular:
                    J[:, 3:, col] = axis
            else:
                J[:, :3, col] = axis
        return J

    @cached_property
    def _bodies(self) -> list[tuple[int, float, np.ndarray]]:
        return [(j, self.model.inertias[j].mass, np.append(self.model.inertias[j].lever, 1.0))
                for j in range(1, self.model.njoints) if self.model.inertias[j].mass > 0]

    @property
    def mass(self) -> float:
        return float(sum(m for _, m, _ in self._bodies))

    def com(self, q: np.ndarray, jacobian: bool = False):
        """Centre of mass (B, 3); with jacobian=True also its Jacobian (B, 3, n)."""
        q = as_batch(q, self.n)
        world, met = self._world(q, [j for j, _, _ in self._bodies], axes=True)
        com, J = np.zeros((len(q), 3)), np.zeros((len(q), 3, self.n))
        for jid, mass, lever in self._bodies:
            c = (world[jid] @ lever)[:, :3]
            com += mass * c
            if jacobian:
                ancestors = {m.index for a in self._ancestors(jid) for m in self._links[a].motions}
                J += mass * self._point_jacobian(c, {k: met[k] for k in ancestors}, len(q), False)
        com, J = com / self.mass, J / self.mass
        return (com, J) if jacobian else com


def as_batch(q: np.ndarray, n: int) -> np.ndarray:
    """Promote (n,) to (1, n) and check the width."""
    q = np.asarray(q, dtype=float)
    if q.ndim == 1:
        q = q[None]
    if q.ndim != 2 or q.shape[1] != n:
        raise ManifoldgenError(f"expected configurations of shape (B, {n}), got {q.shape}")
    return q


def _joint_axis(jm) -> tuple[str, np.ndarray]:
    short = jm.shortname().removeprefix("JointModel")
    if short in ("RX", "RY", "RZ", "RUBX", "RUBY", "RUBZ", "PX", "PY", "PZ"):
        return short[0], np.eye(3)["XYZ".index(short[-1])]
    if short in ("RevoluteUnaligned", "RevoluteUnboundedUnaligned", "PrismaticUnaligned"):
        return short[0], np.asarray(jm.extract().axis, float)
    raise ManifoldgenError(f"joint type {short} cannot be in a planning group; lock it instead")


def _zyx_quaternion(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(B,) ZYX Euler angles -> (B, 4) quaternions [x, y, z, w] of Rz(yaw) Ry(pitch) Rx(roll)."""
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    return np.stack([sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy], axis=1)


def _motion(m: _Motion, angle: np.ndarray) -> np.ndarray:
    """(B, 4, 4) homogeneous transform of a revolute or prismatic motion."""
    T = np.zeros((len(angle), 4, 4))
    T[:, 3, 3] = 1.0
    if m.kind == "P":
        T[:, :3, :3] = np.eye(3)
        T[:, :3, 3] = angle[:, None] * m.axis
        return T
    x, y, z = m.axis
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    T[:, :3, :3] = np.eye(3) + s * K + (1 - c) * (K @ K)
    return T


def _set_joint(model: pin.Model, q: np.ndarray, name: str, value: float) -> None:
    if not model.existJointName(name):
        return
    jm = model.joints[model.getJointId(name)]
    if jm.nq == 1:
        q[jm.idx_q] = value
    elif jm.nq == 2:
        q[jm.idx_q:jm.idx_q + 2] = np.cos(value), np.sin(value)


def _srdf_states(srdf: Path) -> list[tuple[str, dict[str, float]]]:
    """The SRDF's group states as (name, {joint: value})."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(srdf).getroot()
    except ET.ParseError as exc:
        raise ManifoldgenError(f"cannot parse SRDF {srdf}: {exc}") from exc
    states = []
    for state in root.iter("group_state"):
        values = {j.get("name"): float(j.get("value", "0").split()[0]) for j in state.iter("joint")}
        states.append((state.get("name"), values))
    return states
