"""Independent checker for manifoldgen dataset / sample files: pinocchio and coal only.

It reads only the .npz file (``q``, ``y``, ``meta``) and the robot named in it, and
recomputes, row by row, the pose constraint, the joint limits and self-collision
(SRDF-disabled and adjacent pairs skipped), without importing manifoldgen.

    python examples/check_dataset.py pose.npz
    -> pose.npz: 6000 rows; within tolerance 100.00%, within limits 100.00%, self-collision free 100.00%, all three 100.00%
"""

from __future__ import annotations

import json
import site
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin


def robot_files(name: str) -> tuple[Path, Path | None, Path]:
    share = next(Path(p) / "cmeel.prefix" / "share" for p in site.getsitepackages()
                 if (Path(p) / "cmeel.prefix" / "share" / "example-robot-data").is_dir())
    if name.endswith(".urdf"):
        srdf = Path(name).with_suffix(".srdf")
        return Path(name), srdf if srdf.exists() else None, share
    folder = share / "example-robot-data" / "robots" / f"{name}_description"
    srdfs = sorted((folder / "srdf").glob("*.srdf"))
    srdf = folder / "srdf" / f"{name}.srdf"
    return folder / "urdf" / f"{name}.urdf", srdf if srdf.exists() else (srdfs[0] if srdfs else None), share


def load_robot(name: str) -> tuple[pin.Model, pin.GeometryModel]:
    """The robot's model and collision model with its self-collision pairs: all pairs but those
    the SRDF disables and those between adjacent links."""
    urdf, srdf, share = robot_files(name)
    model = pin.buildModelFromUrdf(str(urdf))
    geom = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.COLLISION, package_dirs=[str(share)])
    geom.addAllCollisionPairs()
    if srdf is not None:
        pin.removeCollisionPairs(model, geom, str(srdf))
    keep = []
    for k in range(len(geom.collisionPairs)):
        p = geom.collisionPairs[k]
        ja, jb = geom.geometryObjects[p.first].parentJoint, geom.geometryObjects[p.second].parentJoint
        if ja != jb and model.parents[ja] != jb and model.parents[jb] != ja:
            keep.append(pin.CollisionPair(p.first, p.second))
    geom.removeAllCollisionPairs()
    for p in keep:
        geom.addCollisionPair(p)
    return model, geom


def set_joint(model: pin.Model, q: np.ndarray, name: str, value: float) -> None:
    """One joint value into a pinocchio configuration (continuous joints store cos, sin)."""
    j = model.joints[model.getJointId(name)]
    if j.nq == 2:
        q[j.idx_q:j.idx_q + 2] = np.cos(value), np.sin(value)
    else:
        q[j.idx_q] = value


def check(path: str) -> dict[str, np.ndarray]:
    data = np.load(path, allow_pickle=False)
    meta, q, y = json.loads(str(data["meta"])), data["q"], data["y"]
    model, geom = load_robot(meta["robot"])
    mdata, gdata = model.createData(), pin.GeometryData(geom)

    full = pin.neutral(model)
    for name, value in meta["locked"].items():
        set_joint(model, full, name, value)

    c = meta["constraint"]
    assert c["type"] == "pose", "this checker knows the pose constraint"
    fid, target = model.getFrameId(c["frame"]), np.array(c["rotation"])
    axes = ["xyz".index(a) for a in c["position_axes"]]
    tol_p, tol_r = c["tolerance"]["position"], c["tolerance"]["orientation"]
    ok_tol, ok_lim, ok_col = [], [], []
    for row, cond in zip(q, y):
        limits = True
        for name, value in zip(meta["joints"], row):
            j = model.joints[model.getJointId(name)]
            set_joint(model, full, name, value)
            if j.nq == 1:
                limits &= bool(model.lowerPositionLimit[j.idx_q] - 1e-9 <= value <= model.upperPositionLimit[j.idx_q] + 1e-9)
        pin.framesForwardKinematics(model, mdata, full)
        M = mdata.oMf[fid]
        pos_err = np.abs(M.translation[axes] - cond)
        rot_err = np.abs(pin.log3(target.T @ M.rotation))
        ok_tol.append(bool(np.all(pos_err <= tol_p) and np.all(rot_err <= tol_r)))
        ok_lim.append(limits)
        ok_col.append(not pin.computeCollisions(model, mdata, geom, gdata, full, True))
    return {"tolerance": np.array(ok_tol), "limits": np.array(ok_lim), "collision_free": np.array(ok_col)}


def main(paths: list[str]) -> None:
    for path in paths:
        r = check(path)
        every = r["tolerance"] & r["limits"] & r["collision_free"]
        print(f"{path}: {len(every)} rows; within tolerance {r['tolerance'].mean():.2%}, within limits "
              f"{r['limits'].mean():.2%}, self-collision free {r['collision_free'].mean():.2%}, "
              f"all three {every.mean():.2%}")


if __name__ == "__main__":
    main(sys.argv[1:])
