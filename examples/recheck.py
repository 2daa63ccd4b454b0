"""Shared machinery of the outside checkers (``check_dataset.py``, ``check_path.py``).

Only numpy, pinocchio and coal: no manifoldgen import. Everything comes from a file's ``meta``
(documented in ``docs/file-formats.md``) and the robot's URDF/SRDF, which is located by its
example-robot-data name or the recorded path and verified by content (sha256).

What is rechecked, per configuration ``q (n,)`` of the planning group:

- the constraint: every built-in type's residual ``F(q, y)`` is recomputed with pinocchio (frame
  placements, ``log3``, ``centerOfMass``) and compared component by component to the file's
  ``tolerance``; inequalities ``G(q, y) <= 0`` (balance: CoM inside the support polygon with margin);
  a user type (``"module:Class"``) cannot be rechecked and is reported as such;
- the joint limits (manifoldgen's convention: a continuous or unbounded revolute joint is bounded to
  [-pi, pi]; a floating base's translation by ``base_bounds``, yaw and roll by pi, pitch by pi/2, or by ``base_bounds``'
  columns 4-6 when it has six);
- collisions: the robot's self-collision pairs (all pairs, minus those the SRDF disables, those between
  adjacent links and those whose relative pose the group cannot change; when the SRDF disables almost
  nothing, also those in collision in every one of a few hundred random configurations) and, for
  paths, the scene's obstacles and held tool.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import site
from dataclasses import dataclass, field
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin

EXIT_VALID, EXIT_INVALID, EXIT_USAGE, EXIT_CANNOT = 0, 1, 2, 3
LIMIT_MARGIN = 1e-9  # rad or m, as manifoldgen's within_limits
MAX_METRES = 1e3  # largest scene position coordinate or extent, as manifoldgen's shapes.py
ALWAYS_SAMPLES = 200  # random configurations for the "always colliding" pairs (robots whose SRDF disables few)
BASE_JOINTS = ("base_x", "base_y", "base_z", "base_yaw", "base_pitch", "base_roll")
BUILTIN_TYPES = ("pose", "orientation", "plane", "sphere", "joint_linear", "closed_chain", "rotation", "balance", "set")
AXES = {"x": 0, "y": 1, "z": 2}
# example-robot-data names that no file stem gives: name -> (folder, URDF stem) (as manifoldgen's robot.py)
ALIASES = {"anymal": ("anymal_b_simple_description", "anymal"), "anymal_b": ("anymal_b_simple_description", "anymal"),
           "anymal_c": ("anymal_c_simple_description", "anymal"), "g1": ("g1_description", "g1_29dof_rev_1_0"),
           "so_arm": ("so_arm_description", "so101"), "talos": ("talos_data", "talos_reduced")}


class CannotRecheck(Exception):
    """The file cannot be rechecked at all (unreadable, meta incomplete, robot not found)."""


# ---------------------------------------------------------------------- files
def read_npz(path: str | os.PathLike, arrays: tuple[str, ...]) -> tuple[dict, dict[str, np.ndarray]]:
    """``meta`` (parsed JSON) and the named arrays of a manifoldgen .npz file, as stored (numbers only)."""
    try:
        with np.load(path, allow_pickle=False) as f:
            found = {k: f[k] for k in f.files}
    except Exception as exc:  # numpy and zipfile raise many types for damaged or missing files
        raise CannotRecheck(f"cannot read {path}: {type(exc).__name__}: {exc}") from None
    missing = [k for k in ("meta", *arrays) if k not in found]
    if missing:
        raise CannotRecheck(f"{path} is not a manifoldgen file of this kind: no {', '.join(missing)}")
    try:
        meta = json.loads(str(found.pop("meta")))
    except ValueError as exc:
        raise CannotRecheck(f"{path}: meta is not valid JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise CannotRecheck(f"{path}: meta is not a JSON object")
    for key in ("joints", "constraint"):
        if key not in meta:
            raise CannotRecheck(f"{path}: meta has no '{key}'")
    for k in arrays:
        if found[k].dtype.kind not in "fiu":
            raise CannotRecheck(f"{path}: array '{k}' holds {found[k].dtype}, not numbers; remake the file")
    return meta, {k: found[k] for k in arrays}


def sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def robots_dir() -> Path | None:
    """example-robot-data's ``robots`` folder (the package ships no Python module), or None."""
    roots = [*site.getsitepackages(), site.getusersitepackages(), *Path(pin.__file__).resolve().parents]
    for root in roots:
        path = Path(root) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
        if path.is_dir():
            return path
    return None


def _stem(name: str) -> str:
    return re.sub(r"[^a-z0-9]+", "_", name.lower())


def _named_urdfs(root: Path, name: str) -> list[Path]:
    """URDFs example-robot-data ships under ``name``: an alias, a file stem (with or without ``_robot``),
    or a folder's only (or namesake) URDF."""
    out = []
    if name in ALIASES:
        folder, stem = ALIASES[name]
        out += [u for sub in ("urdf", "robots") for u in [root / folder / sub / f"{stem}.urdf"] if u.is_file()]
    for folder in sorted([*root.glob("*_description"), *root.glob("*_data")]):
        package = folder.name.removesuffix("_description").removesuffix("_data")
        urdfs = [u for sub in ("urdf", "robots") for u in sorted((folder / sub).glob("*.urdf"))]
        for urdf in urdfs:
            stem = _stem(urdf.stem)
            namesake = name == package and (len(urdfs) == 1 or stem == package)
            if name in (stem, stem.removesuffix("_robot")) or namesake:
                out.append(urdf)
    return out


@dataclass
class RobotFiles:
    urdf: Path
    srdf: Path | None
    share: list[str]  # package_dirs for the meshes
    notes: list[str] = field(default_factory=list)  # what was found, and any identity mismatch
    verified: bool = True  # the URDF (and SRDF) have the recorded sha256


def locate_robot(meta: dict, urdf: str | None = None, srdf: str | None = None, near: Path | None = None) -> RobotFiles:
    """The URDF and SRDF of the file's robot: ``urdf``/``srdf`` if given, else the recorded
    ``task.robot_source`` when it is a path (or a file of that name in the folder ``near``, the checked
    file's), else example-robot-data's file of that name, else any example-robot-data URDF with the
    recorded content; every candidate is compared by sha256 with ``task.robot.urdf_sha256`` (and
    ``srdf_sha256``)."""
    task = meta.get("task") if isinstance(meta.get("task"), dict) else {}
    identity = task.get("robot") if isinstance(task.get("robot"), dict) else {}
    name = str(identity.get("name") or meta.get("robot") or "")
    source = str(task.get("robot_source") or meta.get("robot") or "")
    digest, srdf_digest = identity.get("urdf_sha256"), identity.get("srdf_sha256")
    root = robots_dir()
    notes: list[str] = []
    verified = True

    candidates: list[Path] = []
    if urdf is not None:
        if not Path(urdf).is_file():
            raise CannotRecheck(f"--urdf {urdf}: no such file")
        candidates.append(Path(urdf))
    is_path = source.endswith(".urdf") or os.sep in source
    if is_path and Path(source).is_file():
        candidates.append(Path(source))
    if is_path and near is not None and (Path(near) / Path(source).name).is_file():
        candidates.append(Path(near) / Path(source).name)
    if root is not None and name:
        candidates += _named_urdfs(root, name)
    if not is_path and root is not None and source and source != name:
        candidates += _named_urdfs(root, source)
    chosen = None
    if urdf is not None:
        chosen = candidates[0]
    elif digest:
        chosen = next((c for c in candidates if sha256(c) == digest), None)
        if chosen is None and root is not None:  # the same file under another name or folder
            chosen = next((u for u in sorted(root.rglob("*.urdf")) if sha256(u) == digest), None)
    if chosen is None and candidates:
        chosen = candidates[0]
    if chosen is None:
        where = "example-robot-data is not installed" if root is None else f"no URDF named '{name}'"
        raise CannotRecheck(f"robot '{name}' not found ({where}; recorded source {source or '?'}); "
                            "pass --urdf PATH (and --srdf PATH)")
    if digest:
        found = sha256(chosen)
        if found == digest:
            notes.append(f"robot {name}: {chosen} (URDF sha256 {digest[:12]} matches)")
        else:
            verified = False
            notes.append(f"WARNING: URDF sha256 differs: the file was made with {digest[:12]}, {chosen} has "
                         f"{found[:12]}; results are for this URDF, not necessarily the file's robot")
    else:
        notes.append(f"robot {name}: {chosen} (the file records no URDF sha256: identity not verified)")

    # the SRDF: given, recorded, by hash, else the URDF's own (same stem, or the folder's only one)
    srdf_path = None
    if srdf is not None:
        if not Path(srdf).is_file():
            raise CannotRecheck(f"--srdf {srdf}: no such file")
        srdf_path = Path(srdf)
    elif identity and not srdf_digest:
        srdf_path = None  # the robot was loaded without an SRDF
    else:
        options = []
        recorded = task.get("srdf_source")
        if recorded and Path(recorded).is_file():
            options.append(Path(recorded))
        options.append(chosen.with_suffix(".srdf"))
        folder = chosen.parent.parent / "srdf"
        srdfs = sorted(folder.glob("*.srdf")) if folder.is_dir() else []
        by_stem = {s.stem: s for s in srdfs}
        options += [by_stem[s] for s in (chosen.stem, chosen.stem.removesuffix("_robot")) if s in by_stem]
        if len(srdfs) == 1:
            options.append(srdfs[0])
        options += srdfs
        options = [o for o in options if o.is_file()]
        if srdf_digest:
            srdf_path = next((o for o in options if sha256(o) == srdf_digest), None)
            if srdf_path is None and root is not None:
                srdf_path = next((s for s in sorted(root.rglob("*.srdf")) if sha256(s) == srdf_digest), None)
            if srdf_path is None:
                srdf_path = options[0] if options else None
                verified = False
                notes.append(f"WARNING: no SRDF with the recorded sha256 {srdf_digest[:12]}; using "
                             f"{srdf_path or 'none'} for the disabled collision pairs")
        else:
            srdf_path = options[0] if options else None
    if srdf_path is not None and srdf is not None and srdf_digest and sha256(srdf_path) != srdf_digest:
        verified = False
        notes.append(f"WARNING: SRDF sha256 differs from the recorded {srdf_digest[:12]}")
    share = [str(chosen.parent.parent)]
    if root is not None:
        share.insert(0, str(root.parent.parent))
    return RobotFiles(chosen, srdf_path, share, notes, verified)


# ---------------------------------------------------------------------- the robot
class RobotModel:
    """The file's robot: pinocchio model (free flyer when floating), collision model, planning
    group, locked joints, limits; ``full(q)`` maps a group configuration to pinocchio's."""

    def __init__(self, meta: dict, files: RobotFiles):
        task = meta.get("task") if isinstance(meta.get("task"), dict) else {}
        self.files = files
        self.floating_base = bool(meta.get("floating_base", task.get("floating_base", False)))
        try:
            self.model = (pin.buildModelFromUrdf(str(files.urdf), pin.JointModelFreeFlyer()) if self.floating_base
                          else pin.buildModelFromUrdf(str(files.urdf)))
            self.geom = pin.buildGeomFromUrdf(self.model, str(files.urdf), pin.GeometryType.COLLISION,
                                              package_dirs=files.share)
        except (RuntimeError, ValueError) as exc:
            raise CannotRecheck(f"pinocchio cannot load {files.urdf}: {str(exc).splitlines()[0]}") from None
        self.joints = list(meta["joints"])
        self.n = len(self.joints)
        base = list(BASE_JOINTS) if self.floating_base else []
        if self.joints[:len(base)] != base:
            raise CannotRecheck(f"a floating base's coordinates must come first as {base}; meta joints: "
                                f"{self.joints[:6]}")
        self.group_ids = []
        for j in self.joints[len(base):]:
            if not self.model.existJointName(j):
                raise CannotRecheck(f"joint '{j}' of the file is not in {files.urdf}")
            self.group_ids.append(self.model.getJointId(j))
        self.reference = pin.neutral(self.model)
        locked = meta.get("locked", task.get("locked", {})) or {}
        if not isinstance(locked, dict):
            raise CannotRecheck(f"meta 'locked' must map joint names to values, got {locked!r}; remake the file")
        self.locked_problem = None  # a locked joint outside its URDF limits: every configuration is outside
        for j, value in locked.items():
            if not self.model.existJointName(j):
                raise CannotRecheck(f"locked joint '{j}' of the file is not in {files.urdf}")
            if not isinstance(value, (int, float)) or isinstance(value, bool):
                raise CannotRecheck(f"locked joint '{j}' has value {value!r}, not a number; remake the file")
            jm = self.model.joints[self.model.getJointId(j)]
            if jm.nq == 1 and self.locked_problem is None:
                lo, hi = self.model.lowerPositionLimit[jm.idx_q], self.model.upperPositionLimit[jm.idx_q]
                if not lo - LIMIT_MARGIN <= value <= hi + LIMIT_MARGIN:
                    self.locked_problem = f"locked joint {j} = {value:.4f} not in [{lo:.4f}, {hi:.4f}]"
            self._set(self.reference, self.model.getJointId(j), float(value))
        bounds = np.asarray(task.get("base_bounds") or [[-2, -2, -1], [2, 2, 2]], float)
        lower, upper = [], []
        if self.floating_base:  # x, y, z and optionally yaw, pitch, roll (default +-pi, +-pi/2, +-pi)
            angles = np.array([[-np.pi, -np.pi / 2, -np.pi], [np.pi, np.pi / 2, np.pi]])
            if bounds.shape[1] == 6:
                angles = np.clip(bounds[:, 3:], angles[0], angles[1])
            lower += [*bounds[0, :3], *angles[0]]
            upper += [*bounds[1, :3], *angles[1]]
        for jid in self.group_ids:
            jm = self.model.joints[jid]
            if jm.nq == 2:  # continuous: one turn
                lower.append(-np.pi)
                upper.append(np.pi)
            elif jm.nq == 1:
                lo, hi = self.model.lowerPositionLimit[jm.idx_q], self.model.upperPositionLimit[jm.idx_q]
                lower.append(-np.pi if lo < -1e10 else lo)
                upper.append(np.pi if hi > 1e10 else hi)
            else:
                raise CannotRecheck(f"joint '{self.model.names[jid]}' has {jm.nq} coordinates; a planning group "
                                    "holds one-axis joints only")
        self.lower, self.upper = np.array(lower), np.array(upper)
        self.data, self.com_data = self.model.createData(), self.model.createData()
        # the active coordinates moving each joint (the free flyer is joint 1 when floating)
        active = set(self.group_ids) | ({1} if self.floating_base else set())
        self.moving = {0: frozenset()}
        for jid in range(1, self.model.njoints):
            self.moving[jid] = self.moving[self.model.parents[jid]] | ({jid} if jid in active else set())

    def _set(self, full: np.ndarray, jid: int, value: float) -> None:
        jm = self.model.joints[jid]
        if jm.nq == 1:
            full[jm.idx_q] = value
        elif jm.nq == 2:  # continuous joints store cos, sin
            full[jm.idx_q:jm.idx_q + 2] = np.cos(value), np.sin(value)

    def full(self, q: np.ndarray) -> np.ndarray:
        """Group configuration (n,) -> pinocchio configuration (nq,): locked joints at their values; a floating
        base's x, y, z, yaw, pitch, roll -> free flyer translation + quaternion of Rz(yaw) Ry(pitch) Rx(roll)."""
        out = self.reference.copy()
        offset = 0
        if self.floating_base:
            out[:3] = q[:3]
            out[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(q[5], q[4], q[3])).coeffs()  # x, y, z, w
            offset = 6
        for i, jid in enumerate(self.group_ids):
            self._set(out, jid, float(q[offset + i]))
        return out

    def frame(self, name: str) -> int:
        if not isinstance(name, str) or not self.model.existFrame(name):
            raise CannotRecheck(f"frame '{name}' named by the constraint is not in {self.files.urdf}")
        matches = [i for i, f in enumerate(self.model.frames) if f.name == name]
        bodies = [i for i in matches if self.model.frames[i].type == pin.FrameType.BODY]
        return (bodies or matches)[0]  # a link's frame where a joint shares its name, as manifoldgen reads it

    def limit_problem(self, q: np.ndarray) -> str | None:
        """The first coordinate of ``q`` (or, for every ``q``, locked joint) outside its limits, or None."""
        bad = np.flatnonzero((q < self.lower - LIMIT_MARGIN) | (q > self.upper + LIMIT_MARGIN))
        if not len(bad):
            return self.locked_problem
        j = bad[0]
        return f"{self.joints[j]} = {q[j]:.4f} not in [{self.lower[j]:.4f}, {self.upper[j]:.4f}]"


# ---------------------------------------------------------------------- constraints
class State:
    """One configuration with its forward kinematics done once (frames on demand, CoM on demand)."""

    def __init__(self, robot: RobotModel, q: np.ndarray):
        self.robot, self.q, self.full = robot, q, robot.full(q)
        pin.framesForwardKinematics(robot.model, robot.data, self.full)
        self._com = None

    def pose(self, fid: int) -> tuple[np.ndarray, np.ndarray]:
        M = self.robot.data.oMf[fid]
        return M.translation.copy(), M.rotation.copy()

    def com(self) -> np.ndarray:
        if self._com is None:
            self._com = np.array(pin.centerOfMass(self.robot.model, self.robot.com_data, self.full))
        return self._com


def _rotation(value, what: str) -> np.ndarray:
    R = np.asarray(value, float)
    if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise CannotRecheck(f"{what} is not a 3x3 rotation matrix: {value!r}")
    return R


def _unit(value, what: str) -> np.ndarray:
    v = np.asarray(value, float).reshape(-1)
    if v.shape != (3,) or np.linalg.norm(v) < 1e-9:
        raise CannotRecheck(f"{what} is not a non-zero 3-vector: {value!r}")
    return v / np.linalg.norm(v)


def _axes(value, what: str) -> list[int]:
    if not all(a in AXES for a in value):
        raise CannotRecheck(f"{what} must name axes among x, y, z: {value!r}")
    return [AXES[a] for a in value]


class Part:
    """One constraint: ``k`` condition values, ``m`` residual components (tolerances ``tolerance``,
    names ``labels``); ``residual(state, y) (m,)``, ``inequality(state, y) (p,)`` (<= 0)."""

    type = ""
    k = 0
    m = 0
    tolerance: np.ndarray
    labels: list[str]
    recheckable = True

    def residual(self, s: State, y: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def inequality(self, s: State, y: np.ndarray) -> np.ndarray:
        return np.zeros(0)

    def inequality_labels(self) -> list[str]:
        return []


class PosePart(Part):
    """``[p(q)[position_axes] - y, log3(rotation^T R(q))[orientation_axes]]``."""

    type = "pose"

    def __init__(self, robot: RobotModel, spec: dict):
        self.frame_name = spec["frame"]
        self.fid = robot.frame(self.frame_name)
        self.target = _rotation(spec["rotation"], "pose rotation")
        self.pos = _axes(spec.get("position_axes", ["z"]), "pose position_axes")
        self.rot = _axes(spec.get("orientation_axes", ["x", "y", "z"]), "pose orientation_axes")
        self.k, self.m = len(self.pos), len(self.pos) + len(self.rot)
        old = spec.get("tolerance") if isinstance(spec.get("tolerance"), dict) else {}  # format 1 files
        self.tolerance = np.array([spec.get("position_tolerance", old.get("position", 0.01))] * len(self.pos)
                                  + [spec.get("orientation_tolerance", old.get("orientation", 0.01))] * len(self.rot),
                                  float)
        self.labels = ([f"{self.frame_name} position {'xyz'[a]} (m)" for a in self.pos]
                       + [f"{self.frame_name} rotation about {'xyz'[a]} (rad)" for a in self.rot])

    def residual(self, s, y):
        p, R = s.pose(self.fid)
        return np.concatenate([p[self.pos] - y, pin.log3(self.target.T @ R)[self.rot]])


class OrientationPart(Part):
    """``R(q) axis`` along the two unit vectors perpendicular to ``direction`` (2 components), and
    ``-direction . R(q) axis <= 0`` (the axis in direction's hemisphere)."""

    type = "orientation"

    def __init__(self, robot: RobotModel, spec: dict):
        self.frame_name = spec["frame"]
        self.fid = robot.frame(self.frame_name)
        self.axis = _unit(spec.get("axis", (0, 0, 1)), "orientation axis")
        self.direction = _unit(spec.get("direction", (0, 0, 1)), "orientation direction")
        helper = np.eye(3)[0] if abs(self.direction[0]) < 0.9 else np.eye(3)[1]
        e1 = np.cross(self.direction, helper)
        e1 /= np.linalg.norm(e1)
        self.basis = np.stack([e1, np.cross(self.direction, e1)])
        self.k, self.m = 0, 2
        self.tolerance = np.full(2, float(spec.get("tolerance", 0.01)))
        self.labels = [f"{self.frame_name} axis tilt towards e{i} (perpendicular to direction)" for i in (1, 2)]

    def residual(self, s, y):
        _, R = s.pose(self.fid)
        return self.basis @ (R @ self.axis)

    def inequality(self, s, y):
        _, R = s.pose(self.fid)
        return np.array([-self.direction @ (R @ self.axis)])

    def inequality_labels(self):
        return [f"{self.frame_name} axis points away from direction {self.direction.round(3).tolist()}"]


class PlanePart(Part):
    """``N p(q) - y`` for unit normals N (r, 3)."""

    type = "plane"

    def __init__(self, robot: RobotModel, spec: dict):
        self.frame_name = spec["frame"]
        self.fid = robot.frame(self.frame_name)
        N = np.atleast_2d(np.asarray(spec["normals"], float))
        if N.ndim != 2 or N.shape[1] != 3 or not 1 <= len(N) <= 3 or np.any(np.linalg.norm(N, axis=1) < 1e-9):
            raise CannotRecheck(f"plane normals must be 1 to 3 non-zero 3-vectors: {spec['normals']!r}")
        self.normals = N / np.linalg.norm(N, axis=1, keepdims=True)
        self.k = self.m = len(N)
        self.tolerance = np.full(self.m, float(spec.get("tolerance", 0.01)))
        self.labels = [f"{self.frame_name} offset along normal {n.round(3).tolist()} (m)" for n in self.normals]

    def residual(self, s, y):
        p, _ = s.pose(self.fid)
        return self.normals @ p - y


class SpherePart(Part):
    """``|p(q) - c| - y``: the frame's distance from the centre c minus the radius y."""

    type = "sphere"

    def __init__(self, robot: RobotModel, spec: dict):
        self.frame_name = spec["frame"]
        self.fid = robot.frame(self.frame_name)
        self.center = np.asarray(spec.get("center", (0.0, 0.0, 0.0)), float)
        if self.center.shape != (3,):
            raise CannotRecheck(f"sphere center must be 3 numbers: {spec.get('center')!r}")
        self.k = self.m = 1
        self.tolerance = np.array([float(spec.get("tolerance", 0.01))])
        self.labels = [f"{self.frame_name} distance from {self.center.round(3).tolist()} minus the radius (m)"]

    def residual(self, s, y):
        p, _ = s.pose(self.fid)
        return np.array([np.linalg.norm(p - self.center)]) - y


class JointLinearPart(Part):
    """``A q - y`` over the group's coordinates (a floating base's six first)."""

    type = "joint_linear"

    def __init__(self, robot: RobotModel, spec: dict):
        A = np.atleast_2d(np.asarray(spec["coefficients"], float))
        if A.ndim != 2 or A.shape[1] != robot.n:
            raise CannotRecheck(f"joint_linear coefficients must be rows of {robot.n} numbers, got shape {A.shape}")
        self.A = A
        self.k = self.m = len(A)
        self.tolerance = np.full(self.m, float(spec.get("tolerance", 0.01)))
        self.labels = [f"joint_linear row {i}" for i in range(self.m)]

    def residual(self, s, y):
        return self.A @ s.q - y


class RotationPart(Part):
    """``log3((Rot(axis, y) rotation)^T R(q))``: a fixed world rotation turned by the angle y about a world axis."""

    type = "rotation"

    def __init__(self, robot: RobotModel, spec: dict):
        self.frame_name = spec["frame"]
        self.fid = robot.frame(self.frame_name)
        self.base = _rotation(spec["rotation"], "rotation constraint's rotation")
        self.axis = _unit(spec.get("axis", (0, 1, 0)), "rotation constraint's axis")
        self.k, self.m = 1, 3
        self.tolerance = np.full(3, float(spec.get("tolerance", 0.01)))
        self.labels = [f"{self.frame_name} rotation about {a} (rad)" for a in "xyz"]

    def residual(self, s, y):
        _, R = s.pose(self.fid)
        target = pin.exp3(self.axis * float(y[0])) @ self.base
        return pin.log3(target.T @ R)


class ClosedChainPart(Part):
    """``[R_a^T (p_b - p_a) - y axis, log3(rotation^T R_a^T R_b)]``."""

    type = "closed_chain"

    def __init__(self, robot: RobotModel, spec: dict):
        self.a_name, self.b_name = spec["frame_a"], spec["frame_b"]
        self.a, self.b = robot.frame(self.a_name), robot.frame(self.b_name)
        self.target = _rotation(spec["rotation"], "closed chain rotation")
        self.axis = _unit(spec.get("axis", (0, 1, 0)), "closed chain axis")
        self.k, self.m = 1, 6
        self.tolerance = np.array([spec.get("position_tolerance", 0.01)] * 3
                                  + [spec.get("orientation_tolerance", 0.01)] * 3, float)
        self.labels = ([f"{self.b_name} in {self.a_name}, {c} (m)" for c in "xyz"]
                       + [f"{self.b_name} relative rotation about {c} (rad)" for c in "xyz"])

    def residual(self, s, y):
        pa, Ra = s.pose(self.a)
        pb, Rb = s.pose(self.b)
        return np.concatenate([Ra.T @ (pb - pa) - y[0] * self.axis, pin.log3(self.target.T @ Ra.T @ Rb)])


def convex_hull(points: np.ndarray) -> np.ndarray:
    """(P, 2) -> (H, 2) counter-clockwise hull vertices (Andrew's monotone chain)."""
    pts = sorted(set(map(tuple, np.round(points, 9))))
    if len(pts) < 3:
        return np.array(pts)

    def half(seq):
        out = []
        for p in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out[:-1]
    return np.array(half(pts) + half(pts[::-1]))


class BalancePart(Part):
    """Equalities ``[p_foot(q) - foot_position for each foot, (flat feet:) log3(foot_rotation^T R_foot(q)) for each
    foot, p_base(q).z - y]``; inequalities, one per support-polygon edge: ``n_e . com_xy(q) - (n_e . v_e - margin)
    <= 0`` (outward unit normals). The polygon is the hull of the contact points: each foot's ``contacts`` (points
    in the foot frame; default its origin) at the fixed foot pose."""

    type = "balance"

    def __init__(self, robot: RobotModel, spec: dict):
        self.feet = list(spec["feet"])
        self.ids = [robot.frame(f) for f in self.feet]
        self.base_name = spec["base_frame"]
        self.base = robot.frame(self.base_name)
        self.targets = np.asarray(spec["foot_positions"], float).reshape(len(self.feet), 3)
        self.flat = bool(spec.get("flat", False))
        self.rotations = (np.asarray(spec["foot_rotations"], float).reshape(len(self.feet), 3, 3) if self.flat
                          else np.broadcast_to(np.eye(3), (len(self.feet), 3, 3)))
        local = np.asarray(spec.get("contacts") or [[0.0, 0.0, 0.0]], float).reshape(-1, 3)
        self.contacts = (self.targets[:, None] + local @ np.transpose(self.rotations, (0, 2, 1))).reshape(-1, 3)
        self.margin = float(spec.get("margin", 0.02))
        hull = convex_hull(self.contacts[:, :2])
        if len(hull) < 3:
            raise CannotRecheck(f"balance feet {self.feet} span no support polygon")
        edges = np.roll(hull, -1, axis=0) - hull
        self.normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1) / np.linalg.norm(edges, axis=1)[:, None]
        self.offsets = np.einsum("ij,ij->i", self.normals, hull)
        self.hull = hull
        self.k, self.m = 1, 3 * len(self.feet) * (2 if self.flat else 1) + 1
        self.tolerance = np.full(self.m, float(spec.get("tolerance", 0.01)))
        self.labels = ([f"{f} position {c} (m)" for f in self.feet for c in "xyz"]
                       + ([f"{f} rotation about {c} (rad)" for f in self.feet for c in "xyz"] if self.flat else [])
                       + [f"{self.base_name} height (m)"])

    def residual(self, s, y):
        poses = [s.pose(i) for i in self.ids]
        feet = [p - t for (p, _), t in zip(poses, self.targets)]
        turns = [pin.log3(R0.T @ R) for (_, R), R0 in zip(poses, self.rotations)] if self.flat else []
        return np.concatenate([*feet, *turns, s.pose(self.base)[0][2:] - y])

    def inequality(self, s, y):
        return self.normals @ s.com()[:2] - (self.offsets - self.margin)

    def com_depth(self, s) -> float:
        """How far (m) the CoM's ground projection lies inside the support polygon (negative: outside)."""
        return float(np.min(self.offsets - self.normals @ s.com()[:2]))

    def foot_drift(self, s) -> float:
        """The largest distance (m) of a foot from its fixed position."""
        return float(max(np.linalg.norm(s.pose(i)[0] - t) for i, t in zip(self.ids, self.targets)))

    def inequality_labels(self):
        return [f"CoM beyond support edge {a.round(3).tolist()}-{b.round(3).tolist()} less its {self.margin} m margin"
                for a, b in zip(self.hull, np.roll(self.hull, -1, axis=0))]


class UserPart(Part):
    """A type this checker does not know (``module:Class``): not rechecked; ``k``, ``m`` unknown (None)."""

    recheckable = False

    def __init__(self, spec: dict):
        self.type = str(spec.get("type"))
        self.k = self.m = None
        self.tolerance = np.zeros(0)
        self.labels = []


PART_TYPES = {c.type: c for c in (PosePart, OrientationPart, PlanePart, SpherePart, JointLinearPart, ClosedChainPart,
                                   RotationPart, BalancePart)}


def leaves(robot: RobotModel, spec: dict) -> list[Part]:
    """The constraint's parts in order, sets flattened (a set's residual is its parts' concatenated)."""
    if not isinstance(spec, dict) or "type" not in spec:
        raise CannotRecheck(f"constraint spec without a 'type': {spec!r}")
    kind = str(spec["type"])
    if kind == "set":
        return [p for part in spec.get("parts", []) for p in leaves(robot, part)]
    if kind not in PART_TYPES:
        return [UserPart(spec)]
    try:
        return [PART_TYPES[kind](robot, spec)]
    except KeyError as exc:
        raise CannotRecheck(f"constraint '{kind}' spec lacks {exc}") from None


@dataclass
class Verdict:
    """One configuration: ``ok_constraint`` (None: not rechecked), ``ok_limits``, ``ok_collision``;
    ``worst``: max |F_i| / tol_i over the rechecked components; ``reasons``."""

    ok_constraint: bool | None
    ok_limits: bool
    ok_collision: bool
    worst: float
    reasons: list[str]
    inequality_ok: bool = True

    @property
    def ok(self) -> bool:
        return self.ok_constraint is not False and self.ok_limits and self.ok_collision


class ConstraintCheck:
    """The file's constraint on its robot: parts with their slices of ``y`` and of ``tolerance``."""

    def __init__(self, robot: RobotModel, meta: dict, k: int):
        self.spec = meta["constraint"]
        self.parts = leaves(robot, self.spec)
        self.notes: list[str] = []
        if "tolerance" in meta:
            tolerance = np.asarray(meta["tolerance"], float).reshape(-1)
        elif all(p.m is not None for p in self.parts):  # files older than the per-component tolerance
            tolerance = np.concatenate([p.tolerance for p in self.parts])
            self.notes.append("meta has no 'tolerance': using the constraint spec's")
        else:
            raise CannotRecheck("meta has no 'tolerance' and the constraint has a user part")
        unknown = [p for p in self.parts if p.k is None]
        self.user_types = sorted({p.type for p in unknown})
        # an unknown part's k and m follow from the totals when it is the only one
        if len(unknown) == 1:
            unknown[0].k = k - sum(p.k for p in self.parts if p.k is not None)
            unknown[0].m = len(tolerance) - sum(p.m for p in self.parts if p.m is not None)
            if unknown[0].k < 0 or unknown[0].m < 0:
                raise CannotRecheck(f"the condition ({k} values) or tolerance ({len(tolerance)} components) is "
                                    "too short for the constraint's built-in parts")
        self.splittable = len(unknown) <= 1
        self.y_slices, self.tol_slices = [], []
        if self.splittable:
            ky = np.cumsum([0] + [p.k for p in self.parts])
            km = np.cumsum([0] + [p.m for p in self.parts])
            if ky[-1] != k:
                raise CannotRecheck(f"the constraint's parts take {ky[-1]} condition values, the file has {k}")
            if len(tolerance) != km[-1]:
                raise CannotRecheck(f"meta tolerance has {len(tolerance)} components, the constraint spec gives "
                                    f"{km[-1]}")
            self.y_slices = [slice(int(a), int(b)) for a, b in zip(ky[:-1], ky[1:])]
            self.tol_slices = [slice(int(a), int(b)) for a, b in zip(km[:-1], km[1:])]
            for part, s in zip(self.parts, self.tol_slices):
                if part.recheckable:
                    recorded = tolerance[s]
                    if not np.allclose(recorded, part.tolerance):
                        self.notes.append(f"meta tolerance {recorded.tolist()} of the {part.type} part differs from "
                                          f"its spec {part.tolerance.tolist()}; using the smaller")
                    part.tolerance = np.minimum(recorded, part.tolerance)
        self.recheckable = not self.user_types

    def use(self, worst: float, violating: int, what: str = "states") -> str:
        """The constraint's share of a checker's line: the worst use of the tolerance and how many ``what`` violate
        it, or, where a user type was not recomputed, that it was not rechecked (never a 0 that was not measured)."""
        if not self.user_types:
            return f"worst constraint use {worst:.2f} of tolerance, {violating} {what} violating the constraint"
        user = ", ".join(self.user_types)
        if not self.splittable or not any(p.recheckable for p in self.parts):
            return f"constraint NOT rechecked (user type {user})"
        return (f"built-in parts' worst use {worst:.2f} of tolerance, {violating} {what} violating them, user type "
                f"{user} NOT rechecked")

    def describe(self) -> str:
        kind = self.spec.get("type") if isinstance(self.spec, dict) else "?"
        if kind == "set":
            return "set of " + " + ".join(p.type for p in self.parts)
        return str(kind)

    def evaluate(self, s: State, y: np.ndarray) -> tuple[bool | None, float, list[str], bool]:
        """(all rechecked components within tolerance and inequalities <= 0, or None when nothing could be
        rechecked; worst |F|/tol; reasons; inequalities ok)."""
        if not self.splittable:
            return None, 0.0, [], True
        worst, any_checked = 0.0, False
        over, beyond = [], []  # (ratio, text) of components outside tolerance; (G, text) of violated inequalities
        for part, ys in zip(self.parts, self.y_slices):
            if not part.recheckable:
                continue
            any_checked = True
            F = np.asarray(part.residual(s, y[ys]), float)
            if part.m:
                ratio = np.abs(F) / part.tolerance
                worst = max(worst, float(ratio.max()))
                over += [(ratio[i], f"{part.type} {part.labels[i]} residual {F[i]:.4g}, {ratio[i]:.2f} x its "
                                    f"tolerance {part.tolerance[i]:g}") for i in np.flatnonzero(ratio > 1.0)]
            G = np.asarray(part.inequality(s, y[ys]), float)
            labels = part.inequality_labels()
            beyond += [(G[i], f"{part.type} {labels[i]} by {G[i]:.4g}") for i in np.flatnonzero(G > 0)]
        reasons = []
        for what, found in (("constraint", over), ("inequality", beyond)):
            if found:
                found.sort(key=lambda item: -item[0])
                more = f" (and {len(found) - 1} more)" if len(found) > 1 else ""
                reasons.append(f"{what}: {found[0][1]}{more}")
        ineq_ok = not beyond
        if not any_checked:
            return None, worst, [], True
        return not reasons, worst, reasons, ineq_ok


# ---------------------------------------------------------------------- collisions
def _numbers(obj: dict, key: str, size: int, positive: bool = False, metres: bool = True) -> list[float]:
    """Scene object ``obj``'s ``key``: ``size`` finite numbers (positive ones for extents; metres within MAX_METRES),
    as manifoldgen's scenes have (its ``plan`` refuses others); else CannotRecheck naming the object."""
    value = obj.get(key)
    items = value if isinstance(value, list) else [value]
    ok = len(items) == size and all(isinstance(v, (int, float)) and not isinstance(v, bool) and abs(v) < 1e300
                                    for v in items)  # a JSON integer past 1e300 would overflow a float
    if ok:
        a = np.asarray(items, float)
        ok = bool(np.all(np.isfinite(a)) and (not metres or np.all(np.abs(a) <= MAX_METRES))
                  and (not positive or np.all(a > 0)))
    if not ok:
        what = (f"{size if size > 1 else 'a'} {'positive ' * positive}finite number{'s' * (size > 1)}"
                + f" within {MAX_METRES:g} m" * metres)
        raise CannotRecheck(f"scene object '{obj.get('name')}' {key} {value!r} is not {what} (manifoldgen refuses "
                            "such a scene); remake the file")
    return [float(v) for v in items]


def _shape(obj: dict):
    kind = obj.get("type")
    if kind == "box":
        return coal.Box(*_numbers(obj, "size", 3, positive=True))
    if kind == "sphere":
        return coal.Sphere(*_numbers(obj, "radius", 1, positive=True))
    if kind == "cylinder":
        return coal.Cylinder(*_numbers(obj, "radius", 1, positive=True), *_numbers(obj, "length", 1, positive=True))
    if kind == "mesh":
        if not isinstance(obj.get("mesh"), str) or not Path(obj["mesh"]).is_file():
            raise CannotRecheck(f"mesh file {obj.get('mesh')!r} of scene object '{obj.get('name')}' not found")
        scale = _numbers({"scale": [1.0] * 3, **obj}, "scale", 3, positive=True, metres=False)
        return coal.MeshLoader().load(obj["mesh"], np.asarray(scale))
    raise CannotRecheck(f"scene object '{obj.get('name')}' has unknown type {kind!r}")


def _se3(obj: dict) -> pin.SE3:
    """Scene object ``obj``'s pose: finite position within MAX_METRES, unit quaternion (as manifoldgen writes them)."""
    pose = obj.get("pose")
    if not isinstance(pose, dict):
        raise CannotRecheck(f"scene object '{obj.get('name')}' has no pose {{'position', 'quaternion'}}; remake the "
                            "file")
    position = _numbers({"name": obj.get("name"), **pose}, "position", 3)
    x, y, z, w = _numbers({"name": obj.get("name"), "quaternion": [0.0, 0.0, 0.0, 1.0], **pose}, "quaternion", 4,
                          metres=False)
    q = pin.Quaternion(w, x, y, z)
    if abs(q.norm() - 1.0) > 1e-3:
        raise CannotRecheck(f"scene object '{obj.get('name')}' quaternion {[x, y, z, w]} has norm {q.norm():.4f}, "
                            "not 1 (manifoldgen refuses such a scene); remake the file")
    q.normalize()
    return pin.SE3(q.toRotationMatrix(), np.asarray(position))


class Collisions:
    """The checked pairs: robot self-collision, robot (moving links) against world obstacles, the held tool
    against the obstacles and the links outside its touch links (that move relative to it)."""

    def __init__(self, robot: RobotModel, scene: list[dict] | None = None):
        model, geom = robot.model, robot.geom.copy()
        objects = geom.geometryObjects
        count = len(objects)
        geom.addAllCollisionPairs()
        if robot.files.srdf is not None:
            pin.removeCollisionPairs(model, geom, str(robot.files.srdf))
        srdf_disabled = count * (count - 1) // 2 - len(geom.collisionPairs)
        pairs = []
        for i in range(len(geom.collisionPairs)):
            p = geom.collisionPairs[i]
            a, b = int(p.first), int(p.second)
            ja, jb = objects[a].parentJoint, objects[b].parentJoint
            adjacent = ja == jb or model.parents[ja] == jb or model.parents[jb] == ja
            if not adjacent and robot.moving[ja] != robot.moving[jb]:
                pairs.append((a, b))
        self.notes = []
        if srdf_disabled < count:
            pairs, always = self._drop_always(robot, pairs)
            if always:
                self.notes.append(f"the SRDF disables few pairs: {len(always)} pair(s) in collision in every one of "
                                  f"{ALWAYS_SAMPLES} random configurations are not checked")
        geom.removeAllCollisionPairs()
        for a, b in pairs:
            geom.addCollisionPair(pin.CollisionPair(a, b))
        self.self_pairs = len(pairs)
        links = [(i, objects[i].parentJoint, model.frames[objects[i].parentFrame].name) for i in range(count)]
        obstacles, tools = [], []
        for obj in scene or []:
            if "attached_to" in obj:
                fid = robot.frame(obj["attached_to"])
                frame = model.frames[fid]
                gid = geom.addGeometryObject(pin.GeometryObject(str(obj.get("name", "tool")), frame.parentJoint, fid,
                                                                frame.placement * _se3(obj), _shape(obj)))
                tools.append((gid, frame.parentJoint, set(obj.get("touch_links", []))))
            else:
                obstacles.append(geom.addGeometryObject(pin.GeometryObject(str(obj.get("name", "obstacle")), 0, 0,
                                                                           _se3(obj), _shape(obj))))
        for oid in obstacles:
            for i, joint, _ in links:
                if robot.moving[joint]:
                    geom.addCollisionPair(pin.CollisionPair(i, oid))
        for tid, joint, touch in tools:
            for i, parent, link in links:
                if link not in touch and robot.moving[parent] != robot.moving[joint]:
                    geom.addCollisionPair(pin.CollisionPair(i, tid))
            for oid in obstacles:
                geom.addCollisionPair(pin.CollisionPair(tid, oid))
        self.obstacles, self.tools = len(obstacles), len(tools)
        self.robot, self.geom = robot, geom
        self.gdata = pin.GeometryData(geom)
        self.data = model.createData()

    @staticmethod
    def _drop_always(robot: RobotModel, pairs: list[tuple[int, int]]):
        """Pairs colliding at every one of ALWAYS_SAMPLES uniform configurations (MoveIt's "always in
        collision": overlapping meshes), dropped; every other pair stays checked."""
        model, geom = robot.model, robot.geom.copy()
        rng = np.random.default_rng(0)
        candidates = pairs
        for _ in range(ALWAYS_SAMPLES):
            if not candidates:
                break
            geom.removeAllCollisionPairs()
            for a, b in candidates:
                geom.addCollisionPair(pin.CollisionPair(a, b))
            gdata = pin.GeometryData(geom)
            q = robot.full(rng.uniform(robot.lower, robot.upper))
            pin.computeCollisions(model, model.createData(), geom, gdata, q, False)
            candidates = [p for p, r in zip(candidates, gdata.collisionResults) if r.isCollision()]
        always = set(candidates)
        return [p for p in pairs if p not in always], always

    def collides(self, full: np.ndarray) -> bool:
        return bool(pin.computeCollisions(self.robot.model, self.data, self.geom, self.gdata, full, True))

    def names(self, full: np.ndarray) -> list[str]:
        pin.computeCollisions(self.robot.model, self.data, self.geom, self.gdata, full, False)
        objects = self.geom.geometryObjects
        return [f"{objects[p.first].name} with {objects[p.second].name}"
                for p, r in zip(self.geom.collisionPairs, self.gdata.collisionResults) if r.isCollision()]


def with_held(meta: dict, scene: list[dict] | None) -> list[dict]:
    """The scene's objects plus the object the task holds in every scene (``meta.task.attached``: a tray), unless
    the scene already lists it (path files do; datasets have no scene)."""
    if not isinstance(scene or [], list) or not all(isinstance(o, dict) for o in scene or []):
        raise CannotRecheck(f"meta 'scene' must be a list of objects with 'type' and 'pose', got {scene!r:.80}; "
                            "remake the file")
    items = list(scene or [])
    held = (meta.get("task") or {}).get("attached")
    if isinstance(held, dict) and not any(o.get("attached_to") and o.get("name") == held.get("name") for o in items):
        items.append(held)
    return items


# ---------------------------------------------------------------------- one configuration
class Checker:
    """Everything needed to judge configurations of one file: robot, constraint, collisions."""

    def __init__(self, meta: dict, k: int, scene: list[dict] | None = None, urdf: str | None = None,
                 srdf: str | None = None, near: Path | None = None):
        self.meta = meta
        self.files = locate_robot(meta, urdf, srdf, near)
        self.robot = RobotModel(meta, self.files)
        self.constraint = ConstraintCheck(self.robot, meta, k)
        self.collisions = Collisions(self.robot, with_held(meta, scene))
        self.notes = [*self.files.notes, *self.constraint.notes, *self.collisions.notes]
        if self.constraint.user_types:
            what = ", ".join(f"'{t}'" for t in self.constraint.user_types)
            partial = (" (its built-in parts are rechecked)" if self.constraint.splittable and
                       any(p.recheckable for p in self.constraint.parts) else "")
            self.notes.append(f"CANNOT RECHECK the user constraint type {what}: this checker knows only the built-in "
                              f"types ({', '.join(BUILTIN_TYPES)}){partial}; joint limits and collisions are "
                              "still checked")

    def judge(self, q: np.ndarray, y: np.ndarray, explain: bool = False) -> Verdict:
        s = State(self.robot, q)
        ok_c, worst, reasons, ineq_ok = self.constraint.evaluate(s, y)
        limit = self.robot.limit_problem(q)
        if limit:
            reasons.append(f"limits: {limit}")
        collides = self.collisions.collides(s.full)
        if collides:
            pairs = self.collisions.names(s.full) if explain else []
            reasons.append("collision: " + (", ".join(pairs[:3]) or "a checked pair"))
        return Verdict(ok_c, limit is None, not collides, worst, reasons, ineq_ok)


def exit_status(statuses: list[int]) -> int:
    """Several files: invalid wins over could-not-recheck, which wins over valid."""
    if EXIT_INVALID in statuses:
        return EXIT_INVALID
    return EXIT_CANNOT if EXIT_CANNOT in statuses else EXIT_VALID


def print_reports(reports) -> int:
    """Print each file's details and verdict line; return the combined exit status."""
    statuses = []
    for report in reports:
        for line in report["details"]:
            print("  " + line)
        print(report["line"])
        statuses.append(report["status"])
    return exit_status(statuses)
