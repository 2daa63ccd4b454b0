"""Independent checker for manifoldgen path files: pinocchio and coal only.

It reads only the .npz (``path (K, n)`` and ``meta``: robot, joints, locked joints, the pose
constraint, the condition and the scene) and checks every segment interpolated at 0.005 rad
against the constraint tolerance, the joint limits, self-collision (SRDF-disabled and adjacent
pairs skipped) and the recorded obstacles and held tool, without importing manifoldgen.

    python examples/check_path.py p.npz
    -> p.npz: 20 waypoints, 1,144 states checked; worst constraint use 0.87 of tolerance, 0 states in
       collision, 0 outside the limits: VALID
Exit status 1 if any file is invalid.
"""

from __future__ import annotations

import json
import sys

import coal
import numpy as np
import pinocchio as pin

from check_dataset import load_robot, set_joint


def _se3(pose: dict) -> pin.SE3:
    x, y, z, w = pose["quaternion"]
    return pin.SE3(pin.Quaternion(w, x, y, z).toRotationMatrix(), np.array(pose["position"], float))


def _shape(obj: dict):
    if obj["type"] == "box":
        return coal.Box(*obj["size"])
    if obj["type"] == "sphere":
        return coal.Sphere(obj["radius"])
    if obj["type"] == "cylinder":
        return coal.Cylinder(obj["radius"], obj["length"])
    return coal.MeshLoader().load(obj["mesh"], np.array(obj["scale"], float))


def outside_check(file) -> dict:
    """Recheck a path file from its own contents: every segment at 0.005 rad against the pose
    constraint, the joint limits, self-collision (SRDF and adjacent pairs skipped) and the
    recorded scene (obstacles against every robot link; the tool against the obstacles and
    the links outside its touch links)."""
    data = np.load(file, allow_pickle=False)
    meta, path = json.loads(str(data["meta"])), data["path"]
    model, geom = load_robot(meta["robot"])
    links = [(g.parentJoint, model.frames[g.parentFrame].name) for g in geom.geometryObjects]
    robot_ids = range(len(links))
    obstacles, tools = [], []
    for obj in meta["scene"]:
        if "attached_to" in obj:
            frame = model.frames[model.getFrameId(obj["attached_to"])]
            tools.append((geom.addGeometryObject(pin.GeometryObject(obj["name"], frame.parentJoint, frame.placement
                                                                    * _se3(obj["pose"]), _shape(obj))),
                          set(obj["touch_links"])))
        else:
            obstacles.append(geom.addGeometryObject(pin.GeometryObject(obj["name"], 0, _se3(obj["pose"]),
                                                                       _shape(obj))))
    for oid in obstacles:
        for i in robot_ids:
            geom.addCollisionPair(pin.CollisionPair(i, oid))
    for tid, touch in tools:
        for i in robot_ids:
            if links[i][1] not in touch:
                geom.addCollisionPair(pin.CollisionPair(i, tid))
        for oid in obstacles:
            geom.addCollisionPair(pin.CollisionPair(tid, oid))
    gdata, mdata = pin.GeometryData(geom), model.createData()
    spec, y = meta["constraint"], np.array(meta["condition"])
    frame, target = model.getFrameId(spec["frame"]), np.array(spec["rotation"])
    axes = ["xyz".index(a) for a in spec["position_axes"]]
    tol = np.array([spec["tolerance"]["position"]] * len(axes) + [spec["tolerance"]["orientation"]] * 3)
    base = pin.neutral(model)
    for name, value in meta["locked"].items():
        set_joint(model, base, name, value)
    lower = np.array([model.lowerPositionLimit[model.joints[model.getJointId(j)].idx_q] for j in meta["joints"]])
    upper = np.array([model.upperPositionLimit[model.joints[model.getJointId(j)].idx_q] for j in meta["joints"]])
    bounded = np.array([model.joints[model.getJointId(j)].nq == 1 for j in meta["joints"]])
    worst, collisions, outside, states = 0.0, 0, 0, 0
    for a, b in zip(path[:-1], path[1:]):
        steps = max(1, int(np.ceil(np.abs(b - a).max() / 0.005)))
        for t in np.arange(steps + 1) / steps:
            active = a + t * (b - a)
            q = base.copy()
            for name, value in zip(meta["joints"], active):
                set_joint(model, q, name, value)
            outside += bool(np.any(bounded & ((active < lower - 1e-9) | (active > upper + 1e-9))))
            pin.framesForwardKinematics(model, mdata, q)
            placement = mdata.oMf[frame]
            residual = np.concatenate([placement.translation[axes] - y, pin.log3(target.T @ placement.rotation)])
            worst = max(worst, float(np.max(np.abs(residual) / tol)))
            collisions += pin.computeCollisions(model, mdata, geom, gdata, q, True)
            states += 1
    return {"worst": worst, "collisions": collisions, "outside": outside, "states": states, "meta": meta,
            "path": path}


def main(paths: list[str]) -> int:
    failed = 0
    for path in paths:
        r = outside_check(path)
        ok = r["worst"] <= 1.0 and r["collisions"] == 0 and r["outside"] == 0 and len(r["path"]) > 0
        failed += not ok
        print(f"{path}: {len(r['path'])} waypoints, {r['states']:,} states checked; worst constraint use "
              f"{r['worst']:.2f} of tolerance, {r['collisions']} states in collision, {r['outside']} outside the "
              f"limits: {'VALID' if ok else 'INVALID'}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
