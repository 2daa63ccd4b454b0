"""The :class:`Robot`: a pinocchio model (URDF + SRDF) with a planning group of active joints, its limits, and its
batched kinematics (frame poses, Jacobians, centre of mass) on ``q (B, n)`` in numpy (:mod:`.steps`) or torch
(:mod:`.kinematics_torch`). A floating base is six Euclidean coordinates ``(x, y, z, yaw, pitch, roll)`` (ZYX
Euler), mapped to pinocchio's free flyer.
"""

from __future__ import annotations

import contextlib
import difflib
import os
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections import Counter
from functools import cached_property
from pathlib import Path

import numpy as np
import pinocchio as pin

from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot.catalogue import file_sha256, is_path, resolve_robot, robots_dir
from manifoldgen.robot.steps import (Chain, Link, Motion, Step, Tree, as_batch, chain_product, in_chunks,
                                     is_tensor, is_traced, motion_transform, tree_com)

BASE_JOINTS = ("base_x", "base_y", "base_z", "base_yaw", "base_pitch", "base_roll")


_BASE_AXES = (("P", (1, 0, 0)), ("P", (0, 1, 0)), ("P", (0, 0, 1)),
              ("R", (0, 0, 1)), ("R", (0, 1, 0)), ("R", (1, 0, 0)))


# pinocchio joint types that can be in a planning group: one revolute or prismatic axis
_ALIGNED_TYPES = ("RX", "RY", "RZ", "RUBX", "RUBY", "RUBZ", "PX", "PY", "PZ")


_UNALIGNED_TYPES = ("RevoluteUnaligned", "RevoluteUnboundedUnaligned", "PrismaticUnaligned")


_GROUP_TYPES = frozenset(_ALIGNED_TYPES + _UNALIGNED_TYPES)


class Robot:
    """A robot model with a planning group of active joints; the others are locked.

    Build with :meth:`Robot.load`. ``q`` arrays are ``(B, n)`` float64 in the order of
    ``joints``; single configurations ``(n,)`` are accepted and promoted.
    """

    def __init__(self, name: str, model: pin.Model, collision_model: pin.GeometryModel,
                 srdf: Path | None, joints: list[str], reference: np.ndarray,
                 floating_base: bool, base_bounds: np.ndarray, *, source: str, urdf_path: Path):
        self.name = name  # example-robot-data name, or the URDF file stem for a path
        self.source = source  # what was passed to load: a name or a URDF path
        self.urdf_path = urdf_path
        self.model = model
        self.collision_model = collision_model
        self.srdf = srdf
        self._urdf_sha256 = file_sha256(urdf_path)
        self._srdf_sha256 = file_sha256(srdf) if srdf is not None else None
        self.joints = list(joints)
        self.reference = reference  # (model.nq,) full pinocchio configuration for locked joints
        self.floating_base = floating_base
        self._joint_ids = [model.getJointId(j) for j in joints if j not in BASE_JOINTS]
        self.base_bounds = np.asarray(base_bounds, float)  # (2, 3) or (2, 6) floating-base low, high
        self.lower, self.upper = self._limits(base_bounds)
        self._links = self._build_links()
        self._steps, self._anchors = self._build_steps()
        self._chains: dict[str, Chain | np.ndarray] = {}  # frame name -> its chain, or its constant (4, 4) pose
        self._jacobians: tuple[bytes, dict] = (b"", {})  # the latest q's frame Jacobians (see frame_jacobian)

    # ------------------------------------------------------------------ construction
    @classmethod
    def load(cls, robot: str | os.PathLike, joints: list[str] | None = None, *,
             reference: dict[str, float] | None = None, floating_base: bool = False,
             base_bounds: tuple[tuple[float, ...], tuple[float, ...]] = ((-2, -2, -1), (2, 2, 2)),
             srdf: str | os.PathLike | None = None) -> Robot:
        """Load an example-robot-data name (see :func:`known_robots`) or a URDF path.

        joints: the planning group, in order (default: every movable joint that is not a mimic).
        reference: values of locked joints (default: the SRDF's first group state, else neutral).
        floating_base: prepend the six coordinates of ``BASE_JOINTS``, bounded by
        ``base_bounds`` (low, high of x, y, z and optionally yaw, pitch, roll; angles default to ±pi,
        pitch ±pi/2).
        srdf: an SRDF path (default: the robot's own; for a URDF path, the ``.srdf`` beside it).
        """
        source = os.fspath(robot)
        urdf, srdf = resolve_robot(source, srdf)
        name = urdf.stem if is_path(source) else source
        share = str(robots_dir().parent.parent)
        mimics = _urdf_mimics(urdf)  # parses the XML first: a broken file gets our one line, not urdfdom's
        with _native_stderr() as said:
            try:
                model = (pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer()) if floating_base
                         else pin.buildModelFromUrdf(str(urdf)))
                collision = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.COLLISION,
                                                  package_dirs=[share, str(urdf.parent.parent)])
            except (RuntimeError, ValueError) as exc:
                detail = " ".join(said().split()) or str(exc).splitlines()[0]
                raise ManifoldgenError(f"cannot parse URDF {urdf}: {detail}; check that the file is a valid "
                                       "URDF") from exc
        _check_limits(model, urdf)
        joints = _planning_group(model, mimics, name, joints, floating_base)
        q_ref = pin.neutral(model)
        if srdf is not None:
            root = _read_srdf(srdf)
            default = resolve_robot(source)[1]
            _check_srdf_names(root, srdf, model, name, mostly=default is None or srdf.resolve() != default.resolve())
            states = _srdf_states(root)
            for joint, value in (states[0][1].items() if states else []):
                _set_joint(model, q_ref, joint, value)
        for joint, value in (reference or {}).items():
            if not model.existJointName(joint):
                raise ManifoldgenError(f"unknown joint '{joint}' in reference for robot {name}")
            if joint in joints:
                raise ManifoldgenError(f"joint '{joint}' is in the planning group of robot {name}, so it cannot be "
                                       "locked; lock it or plan it, not both (drop it from 'locked' or from 'group')")
            jm = model.joints[model.getJointId(joint)]
            low, high = model.lowerPositionLimit[jm.idx_q], model.upperPositionLimit[jm.idx_q]
            if jm.nq == 1 and not low - 1e-9 <= value <= high + 1e-9:
                raise ManifoldgenError(f"locked joint '{joint}' = {value:g} is outside its limits [{low:g}, {high:g}] "
                                       f"on robot {name}")
            _set_joint(model, q_ref, joint, value)
        return cls(name, model, collision, srdf, joints, q_ref, floating_base,
                   np.asarray(base_bounds, dtype=float), source=source, urdf_path=urdf)

    def _limits(self, base_bounds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lower, upper = [], []
        if self.floating_base:
            angles = np.array([[-np.pi, -np.pi / 2, -np.pi], [np.pi, np.pi / 2, np.pi]])
            bounds = np.asarray(base_bounds, float)
            if bounds.shape not in ((2, 3), (2, 6)) or np.any(bounds[0] > bounds[1]):
                raise ManifoldgenError(f"base_bounds must be [[low], [high]] of x, y, z (and optionally yaw, "
                                       f"pitch, roll), low <= high; got {bounds.tolist()}")
            if bounds.shape[1] == 6:
                angles = np.clip(bounds[:, 3:], angles[0], angles[1])
            lower += [*bounds[0, :3], *angles[0]]
            upper += [*bounds[1, :3], *angles[1]]
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

    def _build_links(self) -> dict[int, Link]:
        model, data = self.model, self.model.createData()
        pin.forwardKinematics(model, data, self.reference)
        col = {jid: i + (6 if self.floating_base else 0) for i, jid in enumerate(self._joint_ids)}
        links = {}
        for jid in range(1, model.njoints):
            jm = model.joints[jid]
            placement = model.jointPlacements[jid].homogeneous
            if self.floating_base and jid == 1:
                motions = tuple(Motion(k, np.array(a, float), i) for i, (k, a) in enumerate(_BASE_AXES))
            elif jid in col:
                kind, axis = _joint_axis(jm)
                motions = (Motion(kind, axis, col[jid]),)
            else:
                placement, motions = data.liMi[jid].homogeneous, ()
            links[jid] = Link(model.parents[jid], placement, motions)
        return links

    def _build_steps(self) -> tuple[list[Step], dict[int, tuple[int, np.ndarray]]]:
        """The elementary motions of ``_links`` in tree order, and per joint id its anchor: (index of the last
        step above it or -1, the fixed (4, 4) transform from that step's frame to the joint's)."""
        steps, anchors = [], {0: (-1, np.eye(4))}
        for jid, link in self._links.items():  # pinocchio numbers a parent before its children
            step, pending = anchors[link.parent]
            pending = pending @ link.placement
            for m in link.motions:
                E = np.zeros((4, 4))
                if m.kind == "R":
                    x, y, z = m.axis
                    E[:3, :3] = [[0, -z, y], [z, 0, -x], [-y, x, 0]]
                else:
                    E[:3, 3] = m.axis
                E2 = E @ E if m.kind == "R" else np.zeros((4, 4))
                steps.append(Step(step, np.stack([pending, pending @ E, pending @ E2]), m.index, m.kind == "R"))
                step, pending = len(steps) - 1, np.eye(4)
            anchors[jid] = (step, pending)
        return steps, anchors

    # ------------------------------------------------------------------ basic facts
    @property
    def identity(self) -> dict[str, str]:
        """``{"name", "urdf_sha256"[, "srdf_sha256"]}``: this robot by file content (see :func:`find_robot`)."""
        out = {"name": self.name, "urdf_sha256": self._urdf_sha256}
        if self._srdf_sha256 is not None:
            out["srdf_sha256"] = self._srdf_sha256
        return out

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
        """Pinocchio frame id, with a clear error for an unknown frame; where a joint and a link share
        the name (z1's gripperStator), the link's (BODY) frame."""
        matches = [i for i, f in enumerate(self.model.frames) if f.name == frame]
        if not matches:
            names = [f.name for f in self.model.frames]
            close = difflib.get_close_matches(str(frame), names, n=3)
            hint = (f"did you mean {', '.join(close)}?" if close
                    else f"`manifoldgen robots {self.name}` lists its frames")
            raise ManifoldgenError(f"unknown frame '{frame}' for robot {self.name}; {hint}")
        bodies = [i for i in matches if self.model.frames[i].type == pin.FrameType.BODY]
        return (bodies or matches)[0]

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

    def joint_poses(self, q: np.ndarray, joint_ids: list[int]) -> dict[int, np.ndarray]:
        """World transforms (B, 4, 4) of the given pinocchio joints and their ancestors, by joint id (0: the world),
        for configurations ``q (B, n)``."""
        return self._world(q, joint_ids)

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
                T = T @ motion_transform(m, q[:, m.index])
            world[jid] = T
        return (world, met) if axes else world

    def frame_pose(self, q: np.ndarray, frame: str) -> tuple[np.ndarray, np.ndarray]:
        """World position (B, 3) and rotation (B, 3, 3) of ``frame``."""
        if is_tensor(q):
            return self.torch_kinematics.frame_pose(q, frame)
        if is_traced(q):
            return q.traced_frame_pose(self, frame)
        q = as_batch(q, self.n)
        chain = self.chain_of(frame)
        if isinstance(chain, np.ndarray):  # nothing in the planning group moves the frame
            T = np.broadcast_to(chain, (len(q), 4, 4)).copy()
        else:
            T = in_chunks(chain_product, chain, q, chain.columns.size)
        return T[:, :3, 3], T[:, :3, :3]

    def chain_of(self, frame: str) -> Chain | np.ndarray:
        """The steps from the world to ``frame`` (see :class:`Chain`), or its constant pose (4, 4); built once."""
        chain = self._chains.get(frame) if isinstance(frame, str) else None
        if chain is None:
            chain = self._chains[frame] = self._chain(self.frame_id(frame))
        return chain

    def _chain(self, fid: int) -> Chain | np.ndarray:
        """The steps from the world to frame ``fid`` (see :class:`Chain`), or its constant pose (4, 4)."""
        f = self.model.frames[fid]
        step, tail = self._anchors[f.parentJoint]
        tail = tail @ f.placement.homogeneous
        path = []
        while step >= 0:
            path.append(step)
            step = self._steps[step].parent
        if not path:
            return tail
        path = path[::-1]
        size = 1 << (len(path) - 1).bit_length()
        constants = np.zeros((3, size, 4, 4))
        constants[0] = np.eye(4)
        for i, index in enumerate(path):
            constants[:, i] = self._steps[index].constants
        constants[:, len(path) - 1] = constants[:, len(path) - 1] @ tail
        columns = np.array([self._steps[i].column for i in path] + [0] * (size - len(path)))
        revolute = np.array([self._steps[i].revolute for i in path] + [True] * (size - len(path)))
        return Chain(constants, columns, revolute, not revolute.all())

    def frame_jacobian(self, q: np.ndarray, frame: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position (B, 3), rotation (B, 3, 3) and world-aligned Jacobian (B, 6, n) of ``frame``.

        Rows 0-2: linear velocity of the frame origin, rows 3-5: angular velocity, both in
        world axes (pinocchio's LOCAL_WORLD_ALIGNED). The results for the latest ``q`` are kept (read-only),
        so the parts of a constraint set that share a frame (the dual-arm tray's) compute it once.
        """
        q = as_batch(q, self.n)
        key = q.tobytes() + str(q.shape).encode()
        if self._jacobians[0] != key:
            self._jacobians = (key, {})
        kept = self._jacobians[1]
        if frame not in kept:
            f = self.model.frames[self.frame_id(frame)]
            world, met = self._world(q, [f.parentJoint], axes=True)
            T = world[f.parentJoint] @ f.placement.homogeneous
            out = (T[:, :3, 3], T[:, :3, :3], self._point_jacobian(T[:, :3, 3], met, len(q), angular=True))
            for a in out:
                a.setflags(write=False)
            kept[frame] = out
        return kept[frame]

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
    def torch_kinematics(self):
        """The differentiable torch path of :meth:`frame_pose` and :meth:`com` (built on first use)."""
        from manifoldgen.robot.kinematics_torch import TorchKinematics
        return TorchKinematics(self)

    @cached_property
    def _bodies(self) -> list[tuple[int, float, np.ndarray]]:
        return [(j, self.model.inertias[j].mass, np.append(self.model.inertias[j].lever, 1.0))
                for j in range(1, self.model.njoints) if self.model.inertias[j].mass > 0]

    @cached_property
    def _tree(self) -> Tree:
        """The steps that move a body and their mass-weighted body points (see :class:`Tree`)."""
        points, fixed = {}, np.zeros(3)  # step -> sum of mass * homogeneous body point in its frame
        for jid, mass, lever in self._bodies:
            step, pending = self._anchors[jid]
            point = mass * (pending @ lever)
            if step < 0:
                fixed += point[:3]
            else:
                points[step] = points.get(step, 0.0) + point
        needed, depth = set(), {}
        for step in points:
            while step >= 0 and step not in needed:
                needed.add(step)
                step = self._steps[step].parent
        for step in sorted(needed):  # a parent step before its children
            parent = self._steps[step].parent
            depth[step] = 0 if parent < 0 else depth[parent] + 1
        order = sorted(needed, key=lambda step: (depth[step], step))  # each depth's steps side by side
        index = {step: i for i, step in enumerate(order)}
        levels = []
        for d in range(1, max(depth.values(), default=0) + 1):
            steps = [index[step] for step in order if depth[step] == d]
            parents = np.array([index[self._steps[order[i]].parent] for i in steps])
            contiguous = np.array_equal(parents, np.arange(parents[0], parents[0] + len(parents)))
            levels.append((slice(steps[0], steps[-1] + 1),
                           slice(parents[0], parents[0] + len(parents)) if contiguous else parents))
        weights = np.zeros((len(order), 4, 4, 3))  # [step, i, j, i] = the step's weighted point's j-th entry
        for i in range(3):
            weights[:, i, :, i] = np.array([points.get(s, np.zeros(4)) for s in order]).reshape(len(order), 4)
        return Tree(np.stack([self._steps[s].constants for s in order], axis=1) if order else np.zeros((3, 0, 4, 4)),
                     np.array([self._steps[s].column for s in order], int),
                     np.array([self._steps[s].revolute for s in order], bool), tuple(levels),
                     weights.reshape(-1, 3), fixed)

    @property
    def mass(self) -> float:
        return float(sum(m for _, m, _ in self._bodies))

    def com(self, q: np.ndarray, jacobian: bool = False):
        """Centre of mass (B, 3); with jacobian=True also its Jacobian (B, 3, n). A tensor ``q``
        takes the differentiable torch path (no Jacobian: autograd gives it)."""
        if is_tensor(q):
            return self.torch_kinematics.com(q)
        if is_traced(q) and not jacobian:
            return q.traced_com(self)
        q = as_batch(q, self.n)
        if not jacobian:
            return in_chunks(tree_com, self._tree, q, self._tree.columns.size) / self.mass
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


def _check_limits(model: pin.Model, urdf: Path) -> None:
    """Refuse a one-coordinate joint of ``urdf`` whose lower limit lies above its upper one."""
    for jid in range(1, model.njoints):
        jm = model.joints[jid]
        low, high = model.lowerPositionLimit[jm.idx_q], model.upperPositionLimit[jm.idx_q]
        if jm.nq == 1 and low > high:
            raise ManifoldgenError(f"joint {model.names[jid]} of {urdf} has lower limit {low:g} above upper {high:g}; "
                                   "fix the URDF")


def _planning_group(model: pin.Model, mimics: dict[str, str], robot: str, joints: list[str] | None,
                    floating_base: bool) -> list[str]:
    """The checked planning group: ``BASE_JOINTS`` first when floating, then ``joints`` in order."""
    base = list(BASE_JOINTS) if floating_base else []
    movable = [model.names[j] for j in range(1, model.njoints) if model.names[j] != "root_joint"
               and _joint_type(model.joints[j]) in _GROUP_TYPES and model.names[j] not in mimics]
    if joints is None:
        if not base and not movable:
            raise ManifoldgenError(f"robot {robot} has no movable joint; "
                                   "load it with floating_base=True to move it as a rigid body")
        return base + movable
    for j, count in Counter(joints).items():
        if count > 1:
            raise ManifoldgenError(f"joint '{j}' is {count} times in the planning group of {robot}; list it once")
    for j in joints:
        if j in BASE_JOINTS:
            if not floating_base:
                raise ManifoldgenError(f"joint '{j}' is a floating-base coordinate but robot {robot} "
                                       "has a fixed base; load it with floating_base=True")
        elif model.existFrame(j) and model.frames[model.getFrameId(j)].type == pin.FrameType.FIXED_JOINT:
            raise ManifoldgenError(f"joint '{j}' of robot {robot} is fixed and cannot move; "
                                   "remove it from the planning group")
        elif not model.existJointName(j):
            close = difflib.get_close_matches(j, movable, n=3)
            hint = f"did you mean {', '.join(close)}?" if close else f"movable joints: {', '.join(movable)}"
            raise ManifoldgenError(f"unknown joint '{j}' for robot {robot}; {hint}")
        elif j in mimics:
            raise ManifoldgenError(f"joint '{j}' of robot {robot} mimics '{mimics[j]}' and cannot move on "
                                   "its own; remove it from the planning group")
        elif (short := _joint_type(model.joints[model.getJointId(j)])) not in _GROUP_TYPES:
            raise ManifoldgenError(f"joint '{j}' of robot {robot} is a {short} joint, which cannot be in a "
                                   "planning group (one revolute or prismatic axis per coordinate); lock it")
    group = base + [j for j in joints if j not in BASE_JOINTS]
    if not group:
        raise ManifoldgenError(f"empty planning group for robot {robot}; name at least one joint, "
                               "or leave joints unset for every movable joint")
    return group


def _urdf_mimics(urdf: Path) -> dict[str, str]:
    """Mimic joint -> the joint it follows, from the URDF's ``<mimic>`` tags.

    pinocchio builds a mimic joint as an independent one unless asked (``mimic=False`` keeps one
    coordinate per joint), so its model alone cannot tell.
    """
    try:
        root = ET.parse(urdf).getroot()
    except ET.ParseError as exc:
        raise ManifoldgenError(f"cannot parse URDF {urdf}: {exc}; check that the file is a valid URDF") from exc
    if root.tag != "robot":
        raise ManifoldgenError(f"cannot parse URDF {urdf}: its root element is <{root.tag}>, not <robot>; check that "
                               "the file is a valid URDF")
    return {j.get("name"): m.get("joint") for j in root.iter("joint") if (m := j.find("mimic")) is not None}


@contextlib.contextmanager
def _native_stderr():
    """Hold what C++ libraries (urdfdom) write to file descriptor 2 while the block runs; yields a
    function returning it, so that a failure says it in our one line. After a block that did not
    raise, what was held (warnings) is written out as usual."""
    sys.stderr.flush()
    saved, held = os.dup(2), tempfile.TemporaryFile()

    def said() -> str:
        held.seek(0)
        return held.read().decode(errors="replace")

    os.dup2(held.fileno(), 2)
    passed = False
    try:
        yield said
        passed = True
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        text = said() if passed else ""
        held.close()
        if text:
            sys.stderr.write(text)


def _joint_type(jm) -> str:
    return jm.shortname().removeprefix("JointModel")


def _joint_axis(jm) -> tuple[str, np.ndarray]:
    """Kind ("R" or "P") and unit axis (3,) in the joint frame of a joint of a ``_GROUP_TYPES`` type."""
    short = _joint_type(jm)
    if short in _UNALIGNED_TYPES:
        return short[0], np.asarray(jm.extract().axis, float)
    return short[0], np.eye(3)["XYZ".index(short[-1])]


def _zyx_quaternion(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(B,) ZYX Euler angles -> (B, 4) quaternions [x, y, z, w] of Rz(yaw) Ry(pitch) Rx(roll)."""
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    return np.stack([sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy], axis=1)


def _set_joint(model: pin.Model, q: np.ndarray, name: str, value: float) -> None:
    if not model.existJointName(name):
        return
    jm = model.joints[model.getJointId(name)]
    if jm.nq == 1:
        q[jm.idx_q] = value
    elif jm.nq == 2:
        q[jm.idx_q:jm.idx_q + 2] = np.cos(value), np.sin(value)


def _read_srdf(srdf: Path) -> ET.Element:
    """The root of an SRDF file: a ``.srdf`` file whose root is ``<robot>`` holding SRDF elements, not a URDF's
    links and joints."""
    if srdf.suffix.lower() != ".srdf":
        raise ManifoldgenError(f"SRDF {srdf} must be a .srdf file (an SRDF's XML), got a '{srdf.suffix}' file; "
                               "give the robot's .srdf")
    try:
        root = ET.parse(srdf).getroot()
    except ET.ParseError as exc:
        raise ManifoldgenError(f"cannot parse SRDF {srdf}: {exc}") from exc
    urdf_tag = next((child.tag for child in root if child.tag in ("link", "joint")), None)
    if root.tag != "robot" or urdf_tag is not None:
        what = f"its root element is <{root.tag}>, not <robot>" if root.tag != "robot" else \
            f"it has a top-level <{urdf_tag}>, as a URDF does"
        raise ManifoldgenError(f"SRDF {srdf} is not an SRDF: {what}; give the robot's .srdf (groups, "
                               "disable_collisions ...)")
    return root


def _check_srdf_names(root: ET.Element, srdf: Path, model: pin.Model, robot: str, mostly: bool) -> None:
    """Refuse an SRDF made for another robot: none of the links and joints it names is the robot's, or (``mostly``:
    an SRDF given that is not the robot's own) most of them are not."""
    names = []
    for element in root.iter():
        if element.tag in ("link", "joint", "passive_joint"):
            names.append(element.get("name"))
        elif element.tag == "disable_collisions":
            names += [element.get("link1"), element.get("link2")]
        elif element.tag == "chain":
            names += [element.get("base_link"), element.get("tip_link")]
    names = list(dict.fromkeys(n for n in names if n))
    known = {frame.name for frame in model.frames}
    unknown = [n for n in names if n not in known]
    if names and (len(unknown) == len(names) or (mostly and 2 * len(unknown) > len(names))):
        raise ManifoldgenError(f"SRDF {srdf.name} is not for robot {robot}: {len(unknown)} of the {len(names)} links "
                               f"and joints it names are not {robot}'s ({', '.join(unknown[:3])}"
                               f"{', ...' if len(unknown) > 3 else ''}); give {robot}'s own SRDF")


def _srdf_states(root: ET.Element) -> list[tuple[str, dict[str, float]]]:
    """The SRDF's group states as (name, {joint: value})."""
    states = []
    for state in root.iter("group_state"):
        values = {j.get("name"): float(j.get("value", "0").split()[0]) for j in state.iter("joint")}
        states.append((state.get("name"), values))
    return states
