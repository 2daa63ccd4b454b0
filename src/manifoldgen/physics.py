"""Physics check of a planned path: does a floating-base robot stay upright when it executes it?

The path is played back quasi-statically in MuJoCo: the robot's own URDF, the floating base
free (a free joint, not fixed), gravity on, a ground plane under its feet, every joint
position-controlled towards the path's values linearly interpolated between waypoints, slowly,
then held. What the base and the feet do is measured: base tilt from the planned orientation,
foot slip along the ground, base drift from the planned position. This is the paper's Gazebo
test made a number.

Why MuJoCo (not pybullet): about 25 MB of wheels with no build step; a URDF importer (``MjSpec``) whose
model we edit before compiling (free joint, ground, servos, contact filters, foot sites) instead of
rewriting the URDF text; servo damping integrated implicitly (``implicitfast``), so stiff position servos
run at a 1 ms step; ``mj_geomDistance`` to set the feet on the ground. It reads centauro's and talos's
example-robot-data URDFs and meshes as they are.

The model (see docs/physics.md):

- links, joints and inertias from the URDF (``inertiafromgeom=false``: the URDF's inertials only,
  as pinocchio; the total mass is checked against pinocchio's); visual geometry is discarded;
- contacts: the feet only. A foot is a frame of the balance constraint; its collision geometry is
  every collision geometry rigidly attached to that frame's link in the plan (through no joint, or down
  through locked joints: centauro's contact frames are on the ankle links, the wheels hang from them on
  locked joints). Every other collision geometry is dropped (the planner already checked self-collision).
  A foot mesh in a format MuJoCo cannot read is rebuilt from the vertices pinocchio (coal) loaded; a foot
  mesh with a flat sole becomes a box, its sole's outline; the contacts are stiffer than MuJoCo's default
  (``contact_timeconst_s``);
- joints: each one a critically damped PD servo (MuJoCo ``general`` actuator, damping integrated
  implicitly, the target taken kv/kp ahead on the plan) whose stiffness is ``(2 pi f)^2 M_jj`` with
  ``M_jj`` the joint's diagonal of the joint-space inertia at the first state (armature included): every joint
  has natural frequency ``f``; a joint with a standing foot beyond it (knee, ankle) carries the rest of the
  robot, and is as stiff as that inertia about its axis at ``stance_frequency_hz`` where that is stiffer. Joints
  outside the planning group are welded at their locked values (their mimic equalities dropped), except
  wheels;
- wheels (``servo_wheels``, on by default): a locked hinge whose child body is part of a foot's contact
  geometry and whose axle is within 15 deg of horizontal at the first state. A disc's angle about its axle
  changes no geometry the plan checks, but welded, a wheel turns with its leg and rolls along the ground.
  Each wheel is servoed instead (same gains) to its locked value plus the angle, about the axle, from the
  world's down direction seen from the wheel's parent link at the first state to the same at the planned
  state (pinocchio's kinematics of the plan): the rim point that touched the ground stays the lowest, the
  wheel does not roll. ``engine["wheel_joints"]`` names them;
- time: segment k gets a nominal duration, the larger of ``seconds_per_rad`` times its largest angle change
  (joints and base angles) and ``seconds_per_m`` times its base translation; each segment is run on a quintic
  ease-in/ease-out from rest to rest (zero velocity and acceleration at both of its waypoints), lasting long
  enough that its peak speed is the nominal one and its peak accelerations stay within ``max_acceleration_rad``
  and ``max_acceleration_m``: no velocity jumps at the waypoints (whose kicks tipped talos over on long paths when
  the whole path was eased as one), and no sharp starts and stops on short segments (whose inertial forces move
  the zero-moment point by about a h / g). The first state is held ``settle_s`` before, the last ``hold_s`` after.

Shapes: a path is ``(K, n)`` in the planning group's coordinates (floating base first).
"""

from __future__ import annotations

import json
import re
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from manifoldgen.errors import ManifoldgenError, require
from manifoldgen.progress import progress_bar
from manifoldgen.robot import Robot, robots_dir

if TYPE_CHECKING:
    from manifoldgen.tasks import Task

_MESH_FORMATS = (".stl", ".obj", ".msh")  # what MuJoCo reads itself
_GAP = 0.005  # m: a foot further above the ground at the start is reported as not touching it
_SOLE_TOL = 0.002  # m: a foot mesh's vertices this close to its lowest (along the foot frame's z) are its sole
_SOLE_MIN = 0.02  # m: a sole narrower than this either way is no flat sole (a wheel's or a rounded foot's line)
_PEAK_SPEED = 1.875  # peak / mean speed of the quintic ease 10u^3 - 15u^4 + 6u^5
_PEAK_ACCELERATION = 10 / np.sqrt(3)  # peak acceleration of the quintic ease over distance D in time T, times T^2 / D


@dataclass(frozen=True)
class PhysicsSettings:
    """How the path is played back, and the verdict's thresholds."""

    seconds_per_rad: float = 2.0  # s per rad of a segment's largest angle change: at most 0.5 rad/s
    seconds_per_m: float = 10.0  # s per m of a segment's base translation: at most 0.1 m/s
    max_acceleration_rad: float = 1.0  # rad/s^2, each joint and base angle (a segment lasts long enough for it) ...
    max_acceleration_m: float = 0.1  # m/s^2 of the base (its CoM's ground projection moves ~ a h / g: 1 cm for talos)
    settle_s: float = 0.5  # s holding the first state before moving
    hold_s: float = 1.0  # s holding the last state after moving
    timestep: float = 0.001  # s, physics step
    control_period: float = 0.005  # s between servo target updates (and measurements)
    frequency_hz: float = 25.0  # natural frequency of every joint servo ...
    stance_frequency_hz: float = 5.0  # ... and of a joint with a standing foot beyond it, on the robot it carries
    damping_ratio: float = 1.0
    armature: float = 0.01  # kg m^2 added to every joint (a geared motor's rotor)
    friction: float = 0.8  # sliding friction coefficient of foot-ground contacts (rubber on concrete ~0.8)
    contact_timeconst_s: float = 0.005  # foot-ground contact stiffness (MuJoCo solref time constant; at least 2 steps)
    tilt_threshold_deg: float = 10.0  # upright: the base tilts less than this from the plan, throughout
    fall_tilt_deg: float = 45.0  # fell: the base tilts more than this ...
    fall_drop_m: float = 0.25  # ... or sinks this far below the plan
    slip_threshold_m: float = 0.02  # stable: upright and no foot slides further than this
    servo_wheels: bool = True  # locked wheels under the feet servoed not to roll (False: welded, as other locked joints)

    def __post_init__(self):
        for name, value in asdict(self).items():
            if not np.isfinite(value) or value < 0 or (value == 0 and name not in ("settle_s", "hold_s", "armature", "servo_wheels")):
                raise ManifoldgenError(f"physics setting {name} must be a positive number, got {value}")
        if self.contact_timeconst_s < 2 * self.timestep:
            raise ManifoldgenError(f"contact_timeconst_s ({self.contact_timeconst_s} s) must be at least two timesteps "
                                   f"({2 * self.timestep} s)")
        if self.control_period < self.timestep:
            raise ManifoldgenError(f"control_period ({self.control_period} s) must be at least the timestep "
                                   f"({self.timestep} s)")


@dataclass
class PhysicsResult:
    """What the robot did when the path was executed in the physics engine."""

    upright: bool  # never fell and max_tilt_deg < tilt_threshold_deg
    stable: bool  # upright and max_slip_m <= slip_threshold_m
    fell: bool
    fell_at_s: float | None  # simulated time of the fall (the run stops there)
    max_tilt_deg: float  # largest angle between the simulated and the planned base z axes
    max_slip_m: float  # largest horizontal displacement of a foot from where it started
    foot_slip_m: dict[str, float]  # per foot frame
    base_drift_m: float  # largest distance between the simulated and the planned base origin
    final_drift_m: float  # the same at the end
    max_tracking_error_rad: float  # largest |joint - servo target| (how well the servos held the path)
    max_effort_ratio: float  # largest |servo torque| / the URDF's effort limit of its joint (> 1: beyond the motor)
    effort_joint: str | None  # the joint where that ratio peaked
    start_foot_gap_m: dict[str, float]  # per foot: its distance to the ground at the first state
    simulated_s: float
    wall_s: float
    cpu_s: float
    engine: dict  # engine name and version, model facts (mass, bodies, contact geometries, what was dropped)
    settings: dict = field(default_factory=dict)  # PhysicsSettings, thresholds included
    path_file: str | None = None

    def to_dict(self) -> dict:
        return asdict(self)


# ---------------------------------------------------------------------- entry points
def check_path_file(path_file: str | Path, settings: PhysicsSettings | None = None, *,
                    feet: list[str] | None = None, progress: bool = False, task: Task | None = None,
                    trust_code: bool = False) -> PhysicsResult:
    """Rebuild the task from the path file's meta (``task``, ``trust_code``: see
    :func:`~manifoldgen.tasks.task_from_meta`) and execute its ``path (K, n)`` (see :func:`check_path`)."""
    from manifoldgen.query import read_path_file

    meta, path, task = read_path_file(path_file, task, trust_code=trust_code)
    if not meta.get("floating_base"):
        raise ManifoldgenError(f"{path_file} is a path of {meta.get('robot', 'a robot')} with a fixed base; the "
                               "physics check needs a floating-base robot standing on its feet (a balance task's path)")
    feet = list(feet) if feet else balance_feet(meta.get("constraint") or {})
    if not feet:
        raise ManifoldgenError(f"{path_file}: its constraint ({(meta.get('constraint') or {}).get('type')}) names no "
                               "feet; give the foot frames (--feet), or check a balance task's path")
    result = check_path(task.robot, path, feet, settings, progress=progress)
    result.path_file = str(path_file)
    return result


def balance_feet(spec: dict) -> list[str]:
    """The foot frames of the first ``balance`` constraint in a constraint spec (nested sets searched)."""
    if spec.get("type") == "balance":
        return list(spec["feet"])
    for part in spec.get("parts", []):
        if found := balance_feet(part):
            return found
    return []


def check_path(robot: Robot, path: np.ndarray, feet: list[str], settings: PhysicsSettings | None = None, *,
               progress: bool = False) -> PhysicsResult:
    """Execute ``path (K, n)`` of a floating-base ``robot`` standing on ``feet`` (frame names) in MuJoCo."""
    settings = settings or PhysicsSettings()
    path = np.asarray(path, float)
    if not robot.floating_base:
        raise ManifoldgenError(f"robot {robot.name} has a fixed base; the physics check needs a floating base")
    if path.ndim != 2 or path.shape[1] != robot.n or len(path) < 1 or not np.isfinite(path).all():
        raise ManifoldgenError(f"the path must be a finite (K, {robot.n}) array for {robot.name}, got {path.shape}")
    wall, cpu = time.perf_counter(), time.process_time()
    sim = _Simulation(robot, feet, settings, path[0])
    result = sim.run(path, progress)
    result.wall_s, result.cpu_s = time.perf_counter() - wall, time.process_time() - cpu
    return result


# ---------------------------------------------------------------------- the model
def _urdf_text(robot: Robot) -> str:
    """The robot's URDF with ``package://`` mesh URIs made absolute (pinocchio's package dirs) and
    MuJoCo's compiler options: keep every link a body, URDF inertials only, no visuals."""
    text = robot.urdf_path.read_text()
    roots = [robots_dir().parent.parent, robot.urdf_path.parent.parent]

    def absolute(match: re.Match) -> str:
        rel = match.group(1)
        found = next((root / rel for root in roots if (root / rel).is_file()), roots[0] / rel)
        return f'filename="{found}"'

    text = re.sub(r'filename="package://([^"]+)"', absolute, text)
    text = re.sub(r'filename="(?!/)([^"]+\.[A-Za-z]+)"',
                  lambda m: f'filename="{(robot.urdf_path.parent / m.group(1)).resolve()}"', text)
    options = ('<mujoco><compiler strippath="false" discardvisual="true" fusestatic="false" '
               'inertiafromgeom="false" balanceinertia="true" boundmass="1e-8" '
               'boundinertia="1e-10"/></mujoco>')
    text, count = re.subn(r"(<robot\b[^>]*>)", lambda m: m.group(1) + options, text, count=1)
    if not count:
        raise ManifoldgenError(f"{robot.urdf_path} has no <robot> element; give a valid URDF")
    return text


def _foot_links(robot: Robot, feet: list[str]) -> dict[str, tuple[str, np.ndarray]]:
    """Foot frame -> (URDF link it is on, frame placement in that link (4, 4))."""
    model = robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    out = {}
    for foot in feet:
        fid = robot.frame_id(foot)
        frame = model.frames[fid]
        if frame.type == pin.FrameType.BODY:
            link = fid
        else:  # a joint's frame: the link that joint carries
            link = next((i for i, f in enumerate(model.frames)
                         if f.type == pin.FrameType.BODY and f.parentFrame == fid), None)
            if link is None:
                raise ManifoldgenError(f"foot frame '{foot}' of {robot.name} carries no link; name a link as the foot")
        out[foot] = (model.frames[link].name, (data.oMf[link].inverse() * data.oMf[fid]).homogeneous)
    return out


def _welded(spec, body, group: set[str]) -> list:
    """The bodies rigidly attached to ``body`` in the plan, ``body`` included: up through bodies with no joint,
    down through bodies with no joint or only joints outside ``group`` (locked: pinocchio holds them rigid)."""
    top = body
    while not top.joints and top.parent is not None and top.parent.name != "world":
        top = top.parent
    found, stack = [], [top]
    while stack:
        b = stack.pop()
        found.append(b)
        stack.extend(c for c in b.bodies if not any(j.name in group for j in c.joints))
    return found


_WHEEL_TILT = np.sin(np.radians(15.0))  # a wheel's axle is within 15 deg of horizontal at the first state


def _find_wheels(spec, mujoco, robot: Robot, group: set[str], foot_bodies: set[str], q0: np.ndarray) -> list:
    """The locked wheels: hinge joints outside ``group`` whose child body is one of the feet's bodies, has collision
    geometry, and whose axle is horizontal (within 15 deg) at ``q0``. Each as (joint name, parent link, axle (3,) unit
    in the parent link's frame)."""
    wheels = []
    for body in spec.bodies:
        if body.name not in foot_bodies or len(body.joints) != 1 or not body.geoms:
            continue
        joint = body.joints[0]
        if joint.name in group or joint.type != mujoco.mjtJoint.mjJNT_HINGE:
            continue
        w, x, y, z = np.asarray(body.quat, float) / np.linalg.norm(body.quat)
        axle = pin.Quaternion(w, x, y, z).matrix() @ (np.asarray(joint.axis, float) / np.linalg.norm(joint.axis))
        R = robot.frame_pose(q0, body.parent.name)[1][0]
        if abs((R @ axle)[2]) <= _WHEEL_TILT:
            wheels.append((joint.name, body.parent.name, axle))
    return wheels


def _weld_locked(spec, mujoco, robot: Robot, group: set[str], keep: set[str] = frozenset()) -> int:
    """Remove every hinge or slide joint outside ``group`` and ``keep``, its child body fixed at the joint's locked
    value (as rigid as pinocchio's locked joints), and the URDF mimic equalities that name one; returns how many."""
    welded = set()
    for body in spec.bodies:
        for joint in list(body.joints):
            if joint.name in group or joint.name in keep or joint.type not in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
                continue
            if len(body.joints) > 1:
                raise ManifoldgenError(f"link {body.name} of {robot.name} has several joints; the physics check "
                                       "takes one joint per link")
            value, axis = robot.locked.get(joint.name, 0.0), np.asarray(joint.axis, float)
            axis = axis / np.linalg.norm(axis)
            motion = pin.SE3.Identity()
            if joint.type == mujoco.mjtJoint.mjJNT_HINGE:
                R = pin.AngleAxis(value, axis).matrix()
                motion = pin.SE3(R, np.asarray(joint.pos, float) - R @ np.asarray(joint.pos, float))
            else:
                motion.translation = value * axis
            w, x, y, z = np.asarray(body.quat, float) / np.linalg.norm(body.quat)
            pose = pin.SE3(pin.Quaternion(w, x, y, z).matrix(), np.asarray(body.pos, float)) * motion
            qx, qy, qz, qw = pin.Quaternion(pose.rotation).coeffs()
            body.pos, body.quat = pose.translation, [qw, qx, qy, qz]
            welded.add(joint.name)
            spec.delete(joint)
    for equality in list(spec.equalities):
        if equality.type == mujoco.mjtEq.mjEQ_JOINT and {equality.name1, equality.name2} & welded:
            spec.delete(equality)
    return len(welded)


class _Simulation:
    """The MuJoCo model of ``robot`` on a ground plane, with servos and foot sites."""

    def __init__(self, robot: Robot, feet: list[str], settings: PhysicsSettings, q0: np.ndarray):
        mujoco = require("mujoco", "physics", "the physics check")
        self.mujoco, self.robot, self.feet, self.settings = mujoco, robot, list(feet), settings
        try:
            spec = mujoco.MjSpec.from_string(_urdf_text(robot))
        except ValueError as exc:
            raise ManifoldgenError(f"MuJoCo cannot read the URDF of {robot.name}: {str(exc).splitlines()[0]}") from exc
        root = spec.worldbody.first_body()
        root.add_freejoint(name="floating_base")
        spec.option.timestep = settings.timestep
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
        links = _foot_links(robot, feet)
        self.joint_names = list(robot.joints[6:])  # servoed, in the group's order
        group = set(self.joint_names)
        foot_geoms, dropped, converted = set(), 0, []
        by_name = {b.name: b for b in spec.bodies}
        foot_bodies = {}
        for foot, (link, placement) in links.items():
            if link not in by_name:
                raise ManifoldgenError(f"MuJoCo's model of {robot.name} has no link '{link}' (foot '{foot}')")
            body = by_name[link]
            foot_bodies[foot] = [b.name for b in _welded(spec, body, group)]
            body.add_site(name=f"foot:{foot}", pos=placement[:3, 3],
                          quat=pin.Quaternion(placement[:3, :3]).coeffs()[[3, 0, 1, 2]])
        contact_bodies = {name for names in foot_bodies.values() for name in names}
        wheels = _find_wheels(spec, mujoco, robot, group, contact_bodies, q0) if settings.servo_wheels else []
        meshes = {m.name: m for m in spec.meshes}
        for body in spec.bodies:
            for geom in list(body.geoms):
                if body.name in contact_bodies:
                    geom.contype, geom.conaffinity, geom.condim = 0, 1, 3
                    geom.friction = [settings.friction, 0.005, 0.0001]
                    geom.solref = [settings.contact_timeconst_s, 1.0]
                    geom.name = geom.name or f"{body.name}:contact{len(foot_geoms)}"
                    foot_geoms.add(geom.name)
                    if geom.type == mujoco.mjtGeom.mjGEOM_MESH:
                        converted += self._convert_mesh(spec, meshes[geom.meshname])
                else:
                    spec.delete(geom)
                    dropped += 1
        spec.worldbody.add_geom(name="ground", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 1],
                                contype=1, conaffinity=1, friction=[settings.friction, 0.005, 0.0001],
                                solref=[settings.contact_timeconst_s, 1.0])
        if not foot_geoms:
            raise ManifoldgenError(f"the feet {feet} of {robot.name} have no collision geometry to stand on; "
                                   "name foot frames on links with <collision> shapes")
        for mesh in list(spec.meshes):
            if not any(g.meshname == mesh.name for g in spec.geoms):
                spec.delete(mesh)
        self.wheel_names = [w[0] for w in wheels]
        self.wheel_parents = [w[1] for w in wheels]
        self._wheel_frames = [robot.model.frames[robot.frame_id(link)] for link in self.wheel_parents]
        self.wheel_axles = np.array([w[2] for w in wheels]).reshape(-1, 3)
        self.wheel_locked = np.array([robot.locked.get(w, 0.0) for w in self.wheel_names])
        servoed = self.joint_names + self.wheel_names  # actuators in this order: the group's joints, then the wheels
        self.servoed = servoed
        welded = _weld_locked(spec, mujoco, robot, group, set(self.wheel_names))
        effort = {}  # the URDF's effort limits, which MuJoCo's importer would enforce: reported, not applied
        for j in spec.joints:
            if j.name in servoed:
                j.armature = settings.armature
                j.limited = mujoco.mjtLimited.mjLIMITED_FALSE  # the servos hold the path; limits were planned
                if j.actfrclimited != mujoco.mjtLimited.mjLIMITED_FALSE and j.actfrcrange[1] > 0:
                    effort[j.name] = float(j.actfrcrange[1])
                j.actfrclimited = mujoco.mjtLimited.mjLIMITED_FALSE
        for name in servoed:
            spec.add_actuator(name=f"servo:{name}", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT,
                              gaintype=mujoco.mjtGain.mjGAIN_FIXED, biastype=mujoco.mjtBias.mjBIAS_AFFINE)
        try:
            soles = self._flat_soles(spec, foot_bodies, foot_geoms)
            self.model = spec.compile()
        except ValueError as exc:
            raise ManifoldgenError(f"MuJoCo cannot compile {robot.name}: {str(exc).splitlines()[0]}") from exc
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.foot_sites = [m.site(f"foot:{f}").id for f in self.feet]
        self.foot_geom_ids = {f: [m.geom(g).id for g in foot_geoms if int(m.geom_bodyid[m.geom(g).id]) in
                                  {m.body(b).id for b in foot_bodies[f]}] for f in self.feet}
        self.root = m.body(root.name).id
        self.ground = m.geom("ground").id
        self.qadr = np.array([m.jnt_qposadr[m.joint(n).id] for n in servoed], int)
        self.dadr = np.array([m.jnt_dofadr[m.joint(n).id] for n in servoed], int)
        self.effort = np.array([effort.get(n, np.inf) for n in servoed])  # (servoed,) N m, inf: none given
        mass = float(m.body_subtreemass[0])
        self.engine = {"engine": "mujoco", "version": mujoco.__version__, "bodies": int(m.nbody - 1),
                       "servoed_joints": len(self.joint_names), "welded_joints": welded,
                       "wheel_joints": list(self.wheel_names), "mass_kg": mass,
                       "pinocchio_mass_kg": robot.mass, "contact_geoms": sorted(foot_geoms), "dropped_geoms": dropped,
                       "meshes_from_pinocchio": converted, "flat_soles": soles}
        if abs(mass - robot.mass) > 1e-6 * max(1.0, robot.mass):
            raise ManifoldgenError(f"MuJoCo's model of {robot.name} weighs {mass:.3f} kg but pinocchio's "
                                   f"{robot.mass:.3f} kg; the URDF's inertials were not read alike")

    def _flat_soles(self, spec, foot_bodies: dict[str, list[str]], foot_geoms: set[str]) -> dict[str, list[float]]:
        """Replace each foot mesh with a flat sole by a box: its sole (x, y extents in the foot frame) and 1 cm thick.

        MuJoCo collides a mesh with the ground plane through its convex hull, and a hull that is flat to a fraction
        of a millimetre (talos's ankle mesh) touches the plane at whichever few vertices are the deepest: talos stood
        on three points per foot, the front one 4.5 cm behind the toe, a support polygon much smaller than the sole.
        A box's bottom face touches at its four corners, the sole's outline. The sole is the foot mesh's vertices
        within ``_SOLE_TOL`` of its lowest along the foot frame's z axis; a footprint narrower than ``_SOLE_MIN`` either
        way (a wheel, a rounded foot) is no flat sole and its mesh is kept. Returns foot -> [x_min, x_max, y_min,
        y_max] (m, foot frame) per box."""
        mujoco = self.mujoco
        meshes = {g.name: g for g in spec.geoms if g.name in foot_geoms and g.type == mujoco.mjtGeom.mjGEOM_MESH}
        if not meshes:
            return {}
        m = spec.compile()
        d = mujoco.MjData(m)
        mujoco.mj_kinematics(m, d)
        soles = {}
        for foot, bodies in foot_bodies.items():
            site = m.site(f"foot:{foot}").id
            R, p = d.site_xmat[site].reshape(3, 3), d.site_xpos[site]
            for name in [n for n in meshes if m.body(int(m.geom_bodyid[m.geom(n).id])).name in bodies]:
                geom, g = meshes[name], m.geom(name).id
                mid = int(m.geom_dataid[g])
                vert = m.mesh_vert[m.mesh_vertadr[mid]:m.mesh_vertadr[mid] + m.mesh_vertnum[mid]].astype(float)
                local = (d.geom_xpos[g] + vert @ d.geom_xmat[g].reshape(3, 3).T - p) @ R  # in the foot frame
                bottom = local[:, 2].min()
                sole = local[local[:, 2] < bottom + _SOLE_TOL]
                lo, hi = sole[:, :2].min(axis=0), sole[:, :2].max(axis=0)
                if (hi - lo).min() < _SOLE_MIN:
                    continue
                half = np.array([*(hi - lo) / 2, 0.005])
                body = int(m.geom_bodyid[g])
                Rb, pb = d.xmat[body].reshape(3, 3), d.xpos[body]
                centre = Rb.T @ (p + R @ np.array([*(hi + lo) / 2, bottom + half[2]]) - pb)  # in the geom's body
                box = spec.body(m.body(body).name).add_geom(
                    name=f"{name}:sole", type=mujoco.mjtGeom.mjGEOM_BOX, size=half, pos=centre,
                    quat=pin.Quaternion(Rb.T @ R).coeffs()[[3, 0, 1, 2]], contype=geom.contype,
                    conaffinity=geom.conaffinity, condim=geom.condim, friction=geom.friction, solref=geom.solref,
                    group=geom.group)
                foot_geoms.discard(name)
                foot_geoms.add(box.name)
                spec.delete(meshes.pop(name))
                soles[foot] = [round(float(v), 4) for v in (lo[0], hi[0], lo[1], hi[1])]
        for mesh in list(spec.meshes):
            if not any(g.meshname == mesh.name for g in spec.geoms):
                spec.delete(mesh)
        return soles

    def _convert_mesh(self, spec, mesh) -> list[str]:
        """Replace a mesh MuJoCo cannot read by the vertices pinocchio loaded (MuJoCo takes their convex hull)."""
        if Path(mesh.file).suffix.lower() in _MESH_FORMATS:
            return []
        for obj in self.robot.collision_model.geometryObjects:
            if Path(obj.meshPath).resolve() == Path(mesh.file).resolve() and hasattr(obj.geometry, "vertices"):
                mesh.uservert = np.asarray(obj.geometry.vertices(), float).ravel()
                mesh.file, mesh.scale = "", [1.0, 1.0, 1.0]
                return [Path(obj.meshPath).name]
        raise ManifoldgenError(f"MuJoCo cannot read the foot mesh {mesh.file} and pinocchio loaded no vertices for it; "
                               "convert it to STL or OBJ")

    # ------------------------------------------------------------------ state
    def _qpos(self, q: np.ndarray) -> np.ndarray:
        """MuJoCo qpos (nq,) of a group configuration q (n,): free joint pose (quaternion w, x, y, z), joints."""
        qpos = self.model.qpos0.copy()
        qpos[:3] = q[:3]
        R = pin.rpy.rpyToMatrix(q[5], q[4], q[3])
        x, y, z, w = pin.Quaternion(R).coeffs()
        qpos[3:7] = w, x, y, z
        qpos[self.qadr] = self._targets(q)
        return qpos

    def _targets(self, q: np.ndarray) -> np.ndarray:
        """Servo targets (servoed,) at the planned configuration q (n,): the group's joints as planned, then each
        wheel at its locked value plus the angle, about its axle, from the world's down direction seen from the wheel's
        parent link at the first state to the same at q (both from pinocchio's kinematics of the plan): the wheel's
        rim point that touched the ground at the first state stays the lowest one, so the wheel does not roll."""
        if not self.wheel_names:
            return q[6:]
        angles = np.empty(len(self.wheel_names))
        for i, (down, axle) in enumerate(zip(self._downs(q), self.wheel_axles)):
            down = down - (down @ axle) * axle
            ref = self._wheel_down[i]
            if np.linalg.norm(down) < 1e-9:  # axle vertical: keep the previous angle
                angles[i] = self._wheel_angle[i]
                continue
            angle = np.arctan2(axle @ np.cross(ref, down), ref @ down)
            angles[i] = angle + 2 * np.pi * np.round((self._wheel_angle[i] - angle) / (2 * np.pi))  # continuous
        self._wheel_angle = angles
        return np.concatenate([q[6:], self.wheel_locked + angles])

    def _downs(self, q: np.ndarray) -> np.ndarray:
        """(wheels, 3): the world's -z in each wheel's parent link frame at the planned q (n,) (our Robot's kinematics,
        one pass for all wheels)."""
        frames = self._wheel_frames
        world = self.robot.joint_poses(q[None], sorted({f.parentJoint for f in frames}))
        return np.array([-(world[f.parentJoint][0, :3, :3] @ f.placement.rotation)[2] for f in frames]).reshape(-1, 3)

    def _reset_wheels(self, q0: np.ndarray) -> None:
        """The wheels' reference: the world's down direction in each parent link's frame at q0, across the axle."""
        self._wheel_angle = np.zeros(len(self.wheel_names))
        self._wheel_down = []
        for down, axle in zip(self._downs(q0), self.wheel_axles):
            down = down - (down @ axle) * axle
            self._wheel_down.append(down / np.linalg.norm(down))

    def _place(self, q0: np.ndarray) -> tuple[float, dict[str, float]]:
        """Put the robot at q0 with its lowest foot on the ground; returns the height shift and each foot's gap."""
        mujoco, m, d = self.mujoco, self.model, self.data
        self._reset_wheels(q0)
        d.qpos[:] = self._qpos(q0)
        mujoco.mj_kinematics(m, d)
        gaps = {f: min(mujoco.mj_geomDistance(m, d, g, self.ground, 10.0, None) for g in ids)
                for f, ids in self.foot_geom_ids.items()}
        shift = -min(gaps.values())
        d.qpos[2] += shift
        d.qvel[:] = 0
        mujoco.mj_forward(m, d)
        lifted = q0 + np.eye(len(q0))[2] * shift
        feet = np.stack([self.robot.frame_pose(lifted, f)[0][0] for f in self.feet])
        error = max(np.abs(d.site_xpos[self.foot_sites] - feet).max(),
                    np.abs(d.subtree_com[self.root] - self.robot.com(lifted)[0]).max())
        if error > 1e-4:
            raise RuntimeError(f"internal error: MuJoCo's and pinocchio's models of {self.robot.name} differ by "
                               f"{error:.2e} m at the first state (feet or centre of mass)")
        self.engine["model_error_m"] = float(error)
        self.engine["start_shift_m"] = float(shift)  # how far the plan's first state was raised to stand on the ground
        return shift, {f: gap - min(gaps.values()) for f, gap in gaps.items()}

    def _set_gains(self) -> None:
        """Servo j: stiffness (2 pi f)^2 M_jj and damping 2 zeta (2 pi f) M_jj, at the current state."""
        m, s = self.model, self.settings
        M = np.zeros((m.nv, m.nv))
        self.mujoco.mj_fullM(m, self.data, M)
        inertia = np.diag(M)[self.dadr]
        omega = 2 * np.pi * s.frequency_hz
        kp, kv = omega ** 2 * inertia, 2 * s.damping_ratio * omega * inertia
        stance, omega_s = self._stance_inertia(), 2 * np.pi * s.stance_frequency_hz
        stiffer = omega_s ** 2 * stance > kp
        kp[stiffer], kv[stiffer] = omega_s ** 2 * stance[stiffer], 2 * s.damping_ratio * omega_s * stance[stiffer]
        self.lead = kv / kp  # s: each servo's target is the plan this far ahead (2 zeta / omega)
        self.engine["stance_servos"] = [self.joint_names[i] for i in np.flatnonzero(stiffer)]
        m.actuator_gainprm[:, 0] = kp
        m.actuator_biasprm[:, :3] = np.stack([np.zeros_like(kp), -kp, -kv], axis=1)

    def _stance_inertia(self) -> np.ndarray:
        """Per servoed joint (J,): the inertia it moves when the feet stand on the ground, at the current state.

        ``M_jj`` is the inertia of the joint's subtree (the links beyond it from the base) about its axis: right
        for an arm or the torso, whose far side is free. A joint with a foot beyond it (hip, knee, ankle of a
        standing leg) moves the other way round: its foot is held by the ground, and its torque turns the rest of
        the robot about its axis. Its inertia is that of every link not beyond it (a lower bound: the other foot
        stands too), about its axis, plus armature; 0 for a joint with no foot beyond it, and for the wheels
        (servoed after the group's joints: a wheel turns only itself)."""
        m, d = self.model, self.data
        parent = m.body_parentid
        feet = {int(m.geom_bodyid[g]) for ids in self.foot_geom_ids.values() for g in ids}
        out = np.zeros(len(self.joint_names) + len(self.wheel_names))
        for i, name in enumerate(self.joint_names):
            jid = m.joint(name).id
            top = int(m.jnt_bodyid[jid])
            beyond = np.zeros(m.nbody, bool)
            for b in range(1, m.nbody):  # bodies are numbered parents first
                beyond[b] = b == top or beyond[parent[b]]
            if not any(beyond[f] for f in feet):
                continue
            rest = np.flatnonzero(~beyond[1:]) + 1
            axis, anchor = d.xaxis[jid], d.xanchor[jid]
            arm = d.xipos[rest] - anchor
            arm -= np.outer(arm @ axis, axis)
            local = np.einsum("kij,i->kj", d.ximat[rest].reshape(-1, 3, 3), axis)  # the axis in each body's frame
            out[i] = (float(np.sum(m.body_mass[rest] * np.sum(arm ** 2, axis=1)))
                      + float(np.sum(m.body_inertia[rest] * local ** 2)) + m.dof_armature[self.dadr[i]])
        return out

    # ------------------------------------------------------------------ run
    def schedule(self, path: np.ndarray) -> tuple[np.ndarray, float]:
        """Waypoint stamps (K,) in s from the first, and the motion's duration (see the module doc): segment k lasts
        long enough that its quintic ease keeps every joint within the peak speeds and accelerations."""
        s = self.settings
        step = np.abs(np.diff(path, axis=0))
        angle, shift = step[:, 3:].max(axis=1, initial=0.0), np.linalg.norm(step[:, :3], axis=1)
        duration = np.maximum.reduce([_PEAK_SPEED * s.seconds_per_rad * angle, _PEAK_SPEED * s.seconds_per_m * shift,
                                      np.sqrt(_PEAK_ACCELERATION * angle / s.max_acceleration_rad),
                                      np.sqrt(_PEAK_ACCELERATION * shift / s.max_acceleration_m)])
        stamps = np.concatenate([[0.0], np.cumsum(duration)])
        return stamps, float(stamps[-1])

    def _plan_at(self, path: np.ndarray, stamps: np.ndarray, motion_s: float, t: float) -> np.ndarray:
        """The planned configuration (n,) at simulated time t: held, each segment eased from rest to rest, held."""
        tau = t - self.settings.settle_s
        if tau <= 0 or len(path) == 1:
            return path[0]
        if tau >= motion_s:
            return path[-1]
        k = int(np.searchsorted(stamps, tau, side="right")) - 1  # stamps[k] <= tau < stamps[k + 1]
        u = (tau - stamps[k]) / (stamps[k + 1] - stamps[k])
        return path[k] + u ** 3 * (10 - 15 * u + 6 * u ** 2) * (path[k + 1] - path[k])

    def run(self, path: np.ndarray, progress: bool) -> PhysicsResult:
        mujoco, m, d, s = self.mujoco, self.model, self.data, self.settings
        shift, gaps = self._place(path[0])
        self._set_gains()
        stamps, motion_s = self.schedule(path)
        total = s.settle_s + motion_s + s.hold_s
        substeps = max(1, int(round(s.control_period / s.timestep)))
        ticks = int(np.ceil(total / (substeps * s.timestep)))
        start_feet = d.site_xpos[self.foot_sites].copy()
        max_tilt = max_drift = drift = tracking = 0.0
        effort = np.zeros(len(self.effort))
        slip = np.zeros(len(self.feet))
        fell_at = None
        target = self._targets(self._plan_at(path, stamps, motion_s, d.time))
        with progress_bar("physics", ticks, enabled=progress) as bar:
            for tick in range(ticks):
                for lead in np.unique(self.lead):  # the target kv / kp ahead: the damping does not lag the plan
                    ahead = self.lead == lead
                    d.ctrl[ahead] = self._targets(self._plan_at(path, stamps, motion_s, d.time + lead))[ahead]
                mujoco.mj_step(m, d, substeps)
                q_plan = self._plan_at(path, stamps, motion_s, d.time)
                target = self._targets(q_plan)
                base_plan = q_plan[:3] + [0.0, 0.0, shift]
                R_plan = pin.rpy.rpyToMatrix(q_plan[5], q_plan[4], q_plan[3])
                tilt = np.degrees(np.arccos(np.clip(R_plan[:, 2] @ d.xmat[self.root].reshape(3, 3)[:, 2], -1, 1)))
                drift = float(np.linalg.norm(d.qpos[:3] - base_plan))
                max_tilt, max_drift = max(max_tilt, tilt), max(max_drift, drift)
                slip = np.maximum(slip, np.linalg.norm((d.site_xpos[self.foot_sites] - start_feet)[:, :2], axis=1))
                tracking = max(tracking, float(np.abs(d.qpos[self.qadr] - target).max()))
                effort = np.maximum(effort, np.abs(d.actuator_force) / self.effort)
                bar.advance()
                if tilt > s.fall_tilt_deg or d.qpos[2] < base_plan[2] - s.fall_drop_m:
                    fell_at = float(d.time)
                    break
        fell = fell_at is not None
        upright = not fell and max_tilt < s.tilt_threshold_deg
        return PhysicsResult(
            upright=bool(upright), stable=bool(upright and slip.max() <= s.slip_threshold_m), fell=fell,
            fell_at_s=fell_at, max_tilt_deg=float(max_tilt), max_slip_m=float(slip.max()),
            foot_slip_m={f: float(v) for f, v in zip(self.feet, slip)}, base_drift_m=float(max_drift),
            final_drift_m=float(drift), max_tracking_error_rad=float(tracking), max_effort_ratio=float(effort.max()),
            effort_joint=self.servoed[int(effort.argmax())] if np.isfinite(self.effort).any() else None,
            start_foot_gap_m={f: float(g) for f, g in gaps.items()}, simulated_s=float(d.time),
            wall_s=0.0, cpu_s=0.0, engine=self.engine, settings=asdict(s))


def summary(result: PhysicsResult) -> str:
    """A few lines for the terminal."""
    s = result.settings
    verdict = ("FELL" + (f" at {result.fell_at_s:.2f} s" if result.fell_at_s is not None else "") if result.fell
               else "upright" if result.upright else "tilted")
    lines = [f"{result.path_file or 'path'}: {verdict}; {'stable' if result.stable else 'not stable'} "
             f"(upright: tilt < {s['tilt_threshold_deg']} deg; stable: slip <= {s['slip_threshold_m']} m; fell: tilt > "
             f"{s['fall_tilt_deg']} deg or base {s['fall_drop_m']} m below plan)",
             f"  max base tilt {result.max_tilt_deg:.2f} deg, base drift {result.base_drift_m:.4f} m "
             f"(final {result.final_drift_m:.4f} m), joint tracking error {result.max_tracking_error_rad:.4f} rad",
             f"  largest servo torque {result.max_effort_ratio:.2f} x its joint's URDF effort limit"
             + (f" ({result.effort_joint}; limits not applied)" if result.effort_joint else " (no limits in the URDF)"),
             "  foot slip " + ", ".join(f"{f} {v * 1000:.1f} mm" for f, v in result.foot_slip_m.items()),
             "  foot gap at start " + ", ".join(f"{f} {v * 1000:.1f} mm" for f, v in result.start_foot_gap_m.items())
             + "".join(f"; {f} does not touch the ground: the first state is not a stance on these feet"
                       for f, v in result.start_foot_gap_m.items() if v > _GAP),
             f"  {result.engine['engine']} {result.engine['version']}: {result.engine['mass_kg']:.2f} kg, "
             f"{len(result.engine['contact_geoms'])} contact geometries, {result.engine['dropped_geoms']} other "
             f"collision geometries dropped; {result.simulated_s:.2f} s simulated in {result.wall_s:.2f} s wall, "
             f"{result.cpu_s:.2f} s CPU"]
    if wheels := result.engine.get("wheel_joints"):
        lines.append(f"  wheels servoed not to roll: {', '.join(wheels)}")
    return "\n".join(lines)


def to_json(result: PhysicsResult) -> str:
    return json.dumps(result.to_dict(), indent=2)
