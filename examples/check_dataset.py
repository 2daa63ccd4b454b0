"""Outside checker for manifoldgen dataset and sample files: numpy, pinocchio and coal only.

It reads only the .npz file (``q (N, n)``, ``y (N, k)``, ``meta``; see docs/file-formats.md) and the
robot's URDF/SRDF (found by its example-robot-data name or recorded path, verified by sha256), and
rechecks every row without importing manifoldgen: the constraint's residuals recomputed with
pinocchio for every built-in type (pose, orientation, plane, joint_linear, closed_chain, rotation, balance
and sets of them) against the file's per-component tolerance, its inequalities (balance: CoM inside the
support polygon with margin), the joint limits, self-collision and the object the task holds (a tray:
``meta.task.attached``) against the robot.

    python examples/check_dataset.py pose.npz [more.npz ...] [--urdf PATH] [--srdf PATH] [--show N]
    -> pose.npz: 240 rows, pose on panda; within tolerance 100.00%, within limits 100.00%,
       collision-free 100.00%, all three 100.00%: VALID

Exit status: 0 every row of every file valid; 1 some row invalid; 2 bad usage; 3 could not recheck
(a user constraint type ``module:Class``, the robot not found or not the file's, an unreadable file).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from recheck import (EXIT_CANNOT, EXIT_INVALID, EXIT_VALID, CannotRecheck, Checker,  # noqa: E402
                     print_reports, read_npz)


def check(path: str | Path, urdf: str | None = None, srdf: str | None = None, show: int = 5) -> dict:
    """Recheck one dataset / sample file. Returns ``status`` (exit code), ``line`` (the verdict),
    ``details`` (notes and the first ``show`` invalid rows), ``rows``, and per row (N,) bool arrays
    ``tolerance`` (None when the constraint is not rechecked), ``limits``, ``collision_free``, ``valid``."""
    try:
        meta, arrays = read_npz(path, ("q", "y"))
        q, y = np.asarray(arrays["q"], float), np.asarray(arrays["y"], float)
        if q.ndim != 2 or y.ndim != 2 or len(q) != len(y) or q.shape[1] != len(meta["joints"]):
            raise CannotRecheck(f"inconsistent shapes q {q.shape}, y {y.shape} for {len(meta['joints'])} joints")
        contradiction = task_copy_contradiction(meta)
        if contradiction:
            raise CannotRecheck(contradiction)
        checker = Checker(meta, y.shape[1], urdf=urdf, srdf=srdf, near=Path(path).parent)
    except CannotRecheck as exc:
        return {"status": EXIT_CANNOT, "line": f"{path}: CANNOT RECHECK: {exc}", "details": [], "rows": 0}
    details = [f"note: {n}" for n in checker.notes]
    tol, lim, col = [], [], []
    shown = 0
    for i, (row, cond) in enumerate(zip(q, y)):
        if not (np.all(np.isfinite(row)) and np.all(np.isfinite(cond))):
            tol.append(False), lim.append(False), col.append(False)
            details.append(f"row {i}: NaN or infinite values")
            continue
        v = checker.judge(row, cond, explain=shown < show)
        tol.append(v.ok_constraint)
        lim.append(v.ok_limits)
        col.append(v.ok_collision)
        if not v.ok and shown < show:
            details.append(f"row {i} (y = {cond.round(4).tolist()}): " + "; ".join(v.reasons))
            shown += 1
    n = len(q)
    limits, free = np.array(lim, bool), np.array(col, bool)
    rechecked = n == 0 or all(t is not None for t in tol)
    within = np.array([t is not False for t in tol], bool)
    valid = within & limits & free
    robot = robot_name(meta)
    parts = [f"{n} rows, {checker.constraint.describe()} on {robot}"]
    pct = (lambda a: f"{a.mean():.2%}" if n else "-")
    if rechecked and checker.constraint.recheckable:
        parts.append(f"within tolerance {pct(within)}, within limits {pct(limits)}, collision-free {pct(free)}, "
                     f"all three {pct(valid)}")
    else:
        what = ", ".join(checker.constraint.user_types)
        parts.append(f"constraint NOT rechecked (user type {what})" if not any(
            p.recheckable for p in checker.constraint.parts) or not checker.constraint.splittable else
            f"built-in parts within tolerance {pct(within)}, user type {what} NOT rechecked")
        parts.append(f"within limits {pct(limits)}, collision-free {pct(free)}")
    if not valid.all():
        status, word = EXIT_INVALID, f"INVALID ({int((~valid).sum())} of {n} rows)"
    elif not checker.constraint.recheckable:
        status, word = EXIT_CANNOT, "CANNOT RECHECK the constraint (user type)"
    elif not checker.files.verified:
        status, word = EXIT_CANNOT, "UNVERIFIED (the robot files differ from the file's; see the warning)"
    else:
        status, word = EXIT_VALID, "VALID"
    line = f"{path}: {parts[0]}; {', '.join(parts[1:])}: {word}"
    return {"status": status, "line": line, "details": details, "rows": n,
            "tolerance": np.array(tol, bool) if rechecked and checker.constraint.recheckable else None,
            "limits": limits, "collision_free": free, "valid": valid, "meta": meta}


def robot_name(meta: dict) -> str:
    """The name of the robot the checker loads: the task's (``meta.task.robot.name``), else ``meta.robot``."""
    task = meta.get("task") if isinstance(meta.get("task"), dict) else {}
    identity = task.get("robot") if isinstance(task.get("robot"), dict) else {}
    return str(identity.get("name") or meta.get("robot") or "?")


def task_copy_contradiction(meta: dict) -> str | None:
    """Why the file's top-level copies of its task (``robot``, ``locked``, ``floating_base``, ``constraint``)
    contradict ``meta.task``, or None: the checker reads both, and would check one while naming the other."""
    task = meta.get("task") if isinstance(meta.get("task"), dict) else {}
    for key in ("robot", "locked", "floating_base", "constraint"):
        made = robot_name(meta) if key == "robot" else task.get(key)
        if key in meta and key in task and meta[key] != made:
            return f"meta '{key}' {str(meta[key])[:40]} contradicts its task's {str(made)[:40]}; the file was edited"
    return None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Recheck manifoldgen dataset / sample files (pinocchio + coal only).",
                                     epilog="exit status: 0 valid, 1 invalid, 2 usage, 3 could not recheck")
    parser.add_argument("files", nargs="+", help="dataset or sample .npz files")
    parser.add_argument("--urdf", help="the robot's URDF, when the recorded one cannot be found")
    parser.add_argument("--srdf", help="the robot's SRDF (disabled collision pairs)")
    parser.add_argument("--show", type=int, default=5, help="invalid rows to explain per file (default 5)")
    args = parser.parse_args(argv)
    if args.show < 0:
        parser.error(f"--show must be 0 or more, got {args.show}")
    return print_reports(check(path, args.urdf, args.srdf, args.show) for path in args.files)


if __name__ == "__main__":
    sys.exit(main())
