"""Running a path in MuJoCo: the servoed model on its ground (:class:`Simulation`), the eased schedule, the
measured tilt, slip and drift."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np
import pinocchio as pin

from manifoldgen.errors import ManifoldgenError, require
from manifoldgen.physics.mjcf import (MESH_FORMATS, SOLE_MIN, SOLE_TOL, find_wheels, foot_links, urdf_text, weld_locked,
                                      welded_bodies)
from manifoldgen.physics.settings import PhysicsResult, PhysicsSettings
from manifoldgen.progress import progress_bar
from manifoldgen.robot import Robot


_PEAK_SPEED = 1.875  # peak / mean speed of the quintic ease 10u^3 - 15u^4 + 6u^5


_PEAK_ACCELERATION = 10 / np.sqrt(3)  # peak acceleration of the quintic ease over distance D in time T, times T^2 / D


def schedule(path: np.ndarray, s: PhysicsSettings) -> tuple[np.ndarray, float]:
    """Waypoint stamps (K,) in s from the first, and the motion's duration (see the module doc): segment k lasts
    long enough that its quintic ease keeps every joint within the peak speeds and accelerations."""
    step = np.abs(np.diff(path, axis=0))
    angle, shift = step[:, 3:].max(axis=1, initial=0.0), np.linalg.norm(step[:, :3], axis=1)
    duration = np.maximum.reduce([_PEAK_SPEED * s.seconds_per_rad * angle, _PEAK_SPEED * s.seconds_per_m * shift,
                                  np.sqrt(_PEAK_ACCELERATION * angle / s.max_acceleration_rad),
                                  np.sqrt(_PEAK_ACCELERATION * shift / s.max_acceleration_m)])
    stamps = np.concatenate([[0.0], np.cumsum(duration)])
    return stamps, float(stamps[-1])


class Simulation:
    """The MuJoCo model of ``robot`` on a ground plane, with servos and foot sites."""

    def __init__(self, robot: Robot, feet: list[str], settings: PhysicsSettings, q0: np.ndarray):
        mujoco = require("mujoco", "physics", "the physics check")
        self.mujoco, self.robot, self.feet, self.settings = mujoco, robot, list(feet), settings
        try:
            spec = mujoco.MjSpec.from_string(urdf_text(robot))
        except ValueError as exc:
            raise ManifoldgenError(f"MuJoCo cannot read the URDF of {robot.name}: {str(exc).splitlines()[0]}") from exc
        root = spec.worldbody.first_body()
        root.add_freejoint(name="floating_base")
        spec.option.timestep = settings.timestep
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
        links = foot_links(robot, feet)
        self.joint_names = list(robot.joints[6:])  # servoed, in the group's order
        group = set(self.joint_names)
        foot_geoms, dropped, converted = set(), 0, []
        by_name = {b.name: b for b in spec.bodies}
        foot_bodies = {}
        for foot, (link, placement) in links.items():
            if link not in by_name:
                raise ManifoldgenError(f"MuJoCo's model of {robot.name} has no link '{link}' (foot '{foot}')")
            body = by_name[link]
            foot_bodies[foot] = [b.name for b in welded_bodies(spec, body, group)]
            body.add_site(name=f"foot:{foot}", pos=placement[:3, 3],
                          quat=pin.Quaternion(placement[:3, :3]).coeffs()[[3, 0, 1, 2]])
        contact_bodies = {name for names in foot_bodies.values() for name in names}
        wheels = find_wheels(spec, mujoco, robot, group, contact_bodies, q0) if settings.servo_wheels else []
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
        welded = weld_locked(spec, mujoco, robot, group, set(self.wheel_names))
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
        within ``SOLE_TOL`` of its lowest along the foot frame's z axis; a footprint narrower than ``SOLE_MIN`` either
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
                sole = local[local[:, 2] < bottom + SOLE_TOL]
                lo, hi = sole[:, :2].min(axis=0), sole[:, :2].max(axis=0)
                if (hi - lo).min() < SOLE_MIN:
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
        if Path(mesh.file).suffix.lower() in MESH_FORMATS:
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
        """:func:`schedule` with this simulation's settings."""
        return schedule(path, self.settings)

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
