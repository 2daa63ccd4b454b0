"""Whether a file was made for a constraint: a dataset's, model's or path's ``meta`` against the robot (by URDF
content), planning group, locked joints and constraint specification of the constraint at hand, and a model's copy
of the robot's joint limits."""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING

import numpy as np

from manifoldgen.errors import ManifoldgenError, differences, listed, short

if TYPE_CHECKING:
    from manifoldgen.constraints import Constraint


def check_made_for(meta: dict, constraint: Constraint, what: str) -> None:
    """Refuse a file (``what``: e.g. "model runs/cvae") whose ``meta`` was made for another robot (by URDF
    content), planning group, locked joints or constraint than ``constraint``'s, or whose copies of its task's
    robot, tolerance and condition (:func:`check_task_copies`) were edited."""
    robot = constraint.robot
    spec = meta.get("task") if isinstance(meta.get("task"), dict) else {}
    made = spec.get("robot", {}) if isinstance(spec.get("robot"), dict) else {}
    found = []
    if made.get("urdf_sha256") != robot.identity["urdf_sha256"]:
        name = str(made.get("name", meta.get("robot")))[:40]
        found.append(f"robot {name} (URDF {str(made.get('urdf_sha256'))[:12]}) vs {robot.name} "
                     f"(URDF {robot.identity['urdf_sha256'][:12]})")
    joints = meta.get("joints")
    if joints != robot.joints:
        found.append(_joints(joints, robot.joints))
    locked = meta.get("locked", {})
    if set(locked) != set(robot.locked) or any(abs(locked[j] - v) > 1e-9 for j, v in robot.locked.items()):
        found.append("locked joint values")
    made_spec, spec = json.loads(json.dumps(meta.get("constraint") or {})), json.loads(json.dumps(constraint.spec()))
    if not _same(made_spec, spec):
        keys = sorted(k for k in set(made_spec) | set(spec) if not _same(made_spec.get(k), spec.get(k)))
        found.append(f"constraint {short(made_spec.get('type'))} vs {spec.get('type')}" if "type" in keys
                     else f"constraint {spec.get('type')} differs in {listed(keys, ', ')}")
    if found:
        raise ManifoldgenError(f"{what} was made for another task: {listed(found)}; use one made for this task "
                               "(collect / train on this task)")
    check_task_copies(meta, constraint, what)


def check_model_for(model, constraint: Constraint, what: str = "the model") -> None:
    """:func:`check_made_for` of a trained ``model``'s meta, then refuse a model whose copy of the joint limits
    (its normalisation ``lower`` and ``upper``: what its samples are clamped to) is not the robot's."""
    check_made_for(model.meta, constraint, what)
    robot = constraint.robot
    for key, limits in (("lower", robot.lower), ("upper", robot.upper)):
        given = np.asarray(model.norm[key], float)
        off = np.flatnonzero(np.abs(given - limits) > 1e-9)
        if len(off):
            j = int(off[0])
            more = f" ({len(off) - 1} more joint(s) differ)" if len(off) > 1 else ""
            raise ManifoldgenError(f"{what}: its normalisation '{key}' gives {robot.joints[j]} {given[j]:g}, but the "
                                   f"robot's limit is {limits[j]:g}{more}; the model file was edited (its checksum "
                                   "is not a signature): restore or retrain the model")


def check_task_copies(meta: dict, constraint: Constraint, what: str) -> None:
    """Refuse ``meta`` whose ``robot``, ``tolerance`` or (a dataset's or model's) ``condition`` (names, units,
    values) are not those of ``constraint``, its task's: an outside reader trusts those copies. (A path file's
    ``condition`` is its query's values, checked by its reader.)"""
    condition = constraint.condition
    copies = {"robot": constraint.robot.name, "tolerance": constraint.tolerance.tolist()}
    if isinstance(meta.get("condition"), dict):
        copies["condition"] = {"names": list(condition.names), "units": list(condition.units),
                               "values": condition.grid.tolist()}
    for key, value in copies.items():
        if key in meta and not _same(meta[key], value):
            raise ManifoldgenError(f"{what}: meta '{key}' contradicts its task "
                                   f"({differences(meta[key], value, key, ('in the file', 'by its task'))}); "
                                   "the file was edited: make it again")


def _joints(made, joints: list[str]) -> str:
    """How the file's ``joints`` differ from the robot's: the first few columns that differ, or both counts."""
    if isinstance(made, list) and len(made) == len(joints):
        return f"joints {listed([f'{short(a)} vs {b}' for a, b in zip(made, joints) if a != b], ', ')}"
    return f"{len(made) if isinstance(made, list) else 'no'} joints vs {len(joints)}"


def _same(a, b) -> bool:
    """Whether two JSON values are equal, numbers to 1e-9 relative (a value computed from the robot's kinematics,
    such as a foot position, may differ in its last bits between versions of our kinematics)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and bool not in (type(a), type(b)):
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)
    return a == b
