"""Building the MuJoCo model of a robot from its URDF: mesh paths, foot links, welded and locked joints, wheels."""

from __future__ import annotations

import re

import numpy as np
import pinocchio as pin

from manifoldgen.errors import ManifoldgenError
from manifoldgen.robot import Robot, robots_dir


MESH_FORMATS = (".stl", ".obj", ".msh")  # what MuJoCo reads itself


SOLE_TOL = 0.002  # m: a foot mesh's vertices this close to its lowest (along the foot frame's z) are its sole


SOLE_MIN = 0.02  # m: a sole narrower than this either way is no flat sole (a wheel's or a rounded foot's line)


# ---------------------------------------------------------------------- the model
def urdf_text(robot: Robot) -> str:
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


def foot_links(robot: Robot, feet: list[str]) -> dict[str, tuple[str, np.ndarray]]:
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


def welded_bodies(spec, body, group: set[str]) -> list:
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


def find_wheels(spec, mujoco, robot: Robot, group: set[str], foot_bodies: set[str], q0: np.ndarray) -> list:
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


def weld_locked(spec, mujoco, robot: Robot, group: set[str], keep: set[str] = frozenset()) -> int:
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
