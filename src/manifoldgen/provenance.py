"""Whether a file was made for a constraint: a dataset's, model's or path's ``meta`` against the robot (by URDF
content), planning group, locked joints and constraint specification of the constraint at hand."""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING

from manifoldgen.errors import ManifoldgenError

if TYPE_CHECKING:
    from manifoldgen.constraints import Constraint


def check_made_for(meta: dict, constraint: Constraint, what: str) -> None:
    """Refuse a file (``what``: e.g. "model runs/cvae") whose ``meta`` was made for another robot (by URDF
    content), planning group, locked joints or constraint than ``constraint``'s."""
    robot = constraint.robot
    spec = meta.get("task") if isinstance(meta.get("task"), dict) else {}
    made = spec.get("robot", {}) if isinstance(spec.get("robot"), dict) else {}
    differences = []
    if made.get("urdf_sha256") != robot.identity["urdf_sha256"]:
        differences.append(f"robot {made.get('name', meta.get('robot'))} (URDF {str(made.get('urdf_sha256'))[:12]}) "
                           f"vs {robot.name} (URDF {robot.identity['urdf_sha256'][:12]})")
    if list(meta.get("joints", [])) != list(robot.joints):
        differences.append(f"joints {meta.get('joints')} vs {robot.joints}")
    locked = meta.get("locked", {})
    if set(locked) != set(robot.locked) or any(abs(locked[j] - v) > 1e-9 for j, v in robot.locked.items()):
        differences.append("locked joint values")
    made_spec, spec = json.loads(json.dumps(meta.get("constraint") or {})), json.loads(json.dumps(constraint.spec()))
    if not _same(made_spec, spec):
        keys = sorted(k for k in set(made_spec) | set(spec) if not _same(made_spec.get(k), spec.get(k)))
        differences.append(f"constraint {made_spec.get('type')} vs {spec.get('type')}" if "type" in keys
                           else f"constraint {spec.get('type')} differs in {', '.join(keys)}")
    if differences:
        raise ManifoldgenError(f"{what} was made for another task: {'; '.join(differences)}; use one made for this "
                               "task (collect / train on this task)")


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
