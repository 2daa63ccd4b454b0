"""Outside checker for manifoldgen path files: numpy, pinocchio and coal only.

It reads only the .npz (``path (K, n)`` and ``meta``: the task with its robot identity, joints,
locked joints, constraint spec and tolerance, the query's condition ``y``, start and goal, the scene's
obstacles and held tool, the validation resolution; see docs/file-formats.md) and the robot's
URDF/SRDF, and checks every straight segment between consecutive waypoints at states every
``meta["validation"]["resolution"]`` (Euclidean, in the group's coordinates) against the constraint
(every built-in type recomputed with pinocchio; tolerance per component; inequalities <= 0), the joint
limits, self-collision, the obstacles and the held tool, without importing manifoldgen. For a balance
constraint it also reports static stability state by state: the centre of mass (pinocchio's
``centerOfMass``) against the support polygon of the fixed feet, and how far the feet moved.

    python examples/check_path.py p.npz [more.npz ...] [--urdf PATH] [--srdf PATH] [--resolution R]
    -> p.npz: 20 waypoints, 1,144 states checked every 0.005; worst constraint use 0.87 of tolerance,
       0 states violating the constraint, 0 in collision, 0 outside the limits: VALID

A folder written by ``manifoldgen bench plan`` is rechecked run by run: each solved record's ``path`` in
``runs.jsonl`` with the query meta every run shares (``problem.json``), whoever planned it (OMPL's runs and the
blind baselines' too); unsolved runs have no path and are counted.

Exit status: 0 every path valid; 1 some path invalid; 2 bad usage; 3 could not recheck (a user
constraint type ``module:Class``, the robot not found or not the file's, an unreadable file, or one manifoldgen does
not write: a resolution outside RESOLUTIONS, more than MAX_STATES states, a malformed scene object, another kind).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from recheck import (EXIT_CANNOT, EXIT_INVALID, EXIT_VALID, BalancePart, CannotRecheck, Checker,  # noqa: E402
                     State, print_reports, read_npz)

DEFAULT_RESOLUTION = 0.005  # what manifoldgen used before paths recorded their resolution
RESOLUTIONS = (1e-5, 0.05)  # rad: the resolutions rechecked (manifoldgen writes 0.005; its planners check at 0.05)
MAX_STATES = 1_000_000  # dense states one check may make
ENDPOINT_TOLERANCE = 1e-6


def checked_resolution(value, where: str) -> float:
    """``value`` (from ``where``: the option or a meta key) when it is a number within RESOLUTIONS, else
    CannotRecheck naming it and the range."""
    low, high = RESOLUTIONS
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not low <= value <= high:
        raise CannotRecheck(f"{where} {value!r} is outside the rechecked range [{low:g}, {high:g}] rad; pass "
                            "--resolution R within it")
    return float(value)


def path_kind(meta: dict) -> None:
    """CannotRecheck unless the meta is a path's (``kind`` "path", or absent as in manifoldgen's own reader)."""
    if not isinstance(meta, dict):
        raise CannotRecheck(f"the meta is not a JSON object: {meta!r:.80}")
    if meta.get("kind", "path") != "path":
        raise CannotRecheck(f"meta 'kind' is {meta.get('kind')!r}, not 'path' (check a roadmap with check_roadmap.py, "
                            "a dataset with check_dataset.py)")


def path_resolution(meta: dict, resolution: float | None, source: str = "meta") -> float:
    """The spacing a path is rechecked at: ``resolution`` (--resolution) if given, else the meta's (read from
    ``source``) ``validation.resolution`` (DEFAULT_RESOLUTION when absent), checked by :func:`checked_resolution`."""
    if resolution is not None:
        return checked_resolution(resolution, "--resolution")
    validation = meta.get("validation") or {}
    if not isinstance(validation, dict):
        raise CannotRecheck(f"{source} 'validation' must be an object, got {validation!r:.80}; remake the file")
    return checked_resolution(validation.get("resolution", DEFAULT_RESOLUTION), f"{source} validation.resolution")


def segment_steps(distances: np.ndarray, resolution: float) -> np.ndarray:
    """States each segment of these lengths gets (at least 1), as floats (no overflow), NaN lengths 1."""
    return np.fmax(1.0, np.ceil(np.asarray(distances, float) / resolution))


def within_budget(states: float, resolution: float) -> None:
    """CannotRecheck when a check would make more than MAX_STATES states."""
    if not states <= MAX_STATES:
        raise CannotRecheck(f"checking every {resolution:g} would make {states:,.0f} states, more than the "
                            f"{MAX_STATES:,} allowed; pass a coarser --resolution (at most {RESOLUTIONS[1]:g})")


def densify(path: np.ndarray, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """States every ``resolution`` (Euclidean) along each segment, the last waypoint included -> (M, n) states
    and (M,) the segment of each state; CannotRecheck beyond MAX_STATES states."""
    if len(path) == 1:
        return path.copy(), np.zeros(1, int)
    steps = segment_steps(np.linalg.norm(np.diff(path, axis=0), axis=1), resolution)
    within_budget(steps.sum() + 1, resolution)
    steps = steps.astype(int)
    segment = np.repeat(np.arange(len(steps)), steps)
    t = np.concatenate([np.arange(k) / k for k in steps])
    states = path[segment] + t[:, None] * (path[segment + 1] - path[segment])
    return np.concatenate([states, path[-1:]]), np.append(segment, len(steps) - 1)


def outside_check(file, urdf: str | None = None, srdf: str | None = None, resolution: float | None = None,
                  content: tuple[dict, np.ndarray] | None = None, near: Path | None = None,
                  checker: Checker | None = None) -> dict:
    """Recheck one path file. Returns ``status`` (exit code), ``line`` (verdict), ``details``, ``valid``,
    ``reason`` (the first problem), ``worst`` (max |F_i| / tol_i over the states), ``violations`` (states
    outside tolerance or violating an inequality), ``collisions``, ``outside`` (states outside the limits),
    ``states``, ``resolution``, ``meta``, ``path`` and, for a balance constraint, ``stability`` (``states``,
    ``unstable``: states whose CoM is outside the support polygon, ``min_depth`` m, ``max_foot_drift`` m; else None).
    ``content``: (meta, path) already read (``file`` then only names it); ``near``: where to look for the robot
    files (default: the file's folder); ``checker``: one already made for this meta (many paths of one file)."""
    empty = {"worst": float("inf"), "collisions": 0, "outside": 0, "violations": 0, "states": 0, "valid": False,
             "meta": {}, "path": np.zeros((0, 0)), "details": []}
    try:
        if content is None:
            meta, arrays = read_npz(file, ("path",))
            path_kind(meta)
            path = np.asarray(arrays["path"], float)
        else:
            meta, path = content
        n = len(meta["joints"])
        if path.ndim != 2 or path.shape[1] != n:
            raise CannotRecheck(f"path has shape {path.shape}, expected (K, {n}) for the file's joints")
        y = meta.get("condition")
        if isinstance(y, dict):  # a dataset-style condition table: not a path file
            raise CannotRecheck("meta 'condition' is not the query's condition values (is this a path file?)")
        y = np.asarray(y if y is not None else [], float).reshape(-1)
        resolution = path_resolution(meta, resolution)
        finite = len(path) and np.all(np.isfinite(path))  # else no state is checked: the path is invalid
        states, segment = densify(path, resolution) if finite else (path[:0], np.zeros(0, int))
        checker = checker or Checker(meta, len(y), scene=meta.get("scene") or [], urdf=urdf, srdf=srdf,
                                     near=near or Path(file).parent)
    except CannotRecheck as exc:
        return {**empty, "status": EXIT_CANNOT, "reason": str(exc), "line": f"{file}: CANNOT RECHECK: {exc}"}
    details = [f"note: {note}" for note in checker.notes]
    scene = checker.collisions
    details.append(f"note: collision pairs: {scene.self_pairs} self, {scene.obstacles} obstacle(s), "
                   f"{scene.tools} held object(s)")
    reason = ""
    if len(path) == 0:
        reason = "the path is empty"
    elif not np.all(np.isfinite(path)):
        reason = "the path contains NaN or infinite values"
    else:
        for key, row, what in (("start", path[0], "start"), ("goal", path[-1], "end")):
            if meta.get(key) is not None:
                recorded = np.asarray(meta[key], float)
                if recorded.shape != row.shape or np.abs(recorded - row).max() > ENDPOINT_TOLERANCE:
                    reason = reason or f"the path does not {what} at the recorded {key} {recorded.round(4).tolist()}"
    worst, violations, collisions, outside, count = 0.0, 0, 0, 0, len(states)
    rechecked = True
    balance = [p for p in checker.constraint.parts if isinstance(p, BalancePart)]
    depths, drifts = [], []
    for i, (q, seg) in enumerate(zip(states, segment)):
        if balance:  # static stability with pinocchio's own centre of mass and frame placements
            state = State(checker.robot, q)
            depths.append(min(b.com_depth(state) for b in balance))
            drifts.append(max(b.foot_drift(state) for b in balance))
        v = checker.judge(q, y, explain=not reason)
        worst = max(worst, v.worst)
        rechecked &= v.ok_constraint is not None
        violations += v.ok_constraint is False
        collisions += not v.ok_collision
        outside += not v.ok_limits
        if not v.ok and not reason:
            reason = f"segment {seg} (state {i}): " + "; ".join(v.reasons)
    valid = not reason
    stability = None
    if depths:
        depths_a = np.asarray(depths)
        stability = {"states": len(depths), "unstable": int((depths_a < 0).sum()), "min_depth": float(depths_a.min()),
                     "max_foot_drift": float(max(drifts))}
        details.append(f"balance: the CoM (pinocchio.centerOfMass) is outside the support polygon in "
                       f"{stability['unstable']} of {len(depths)} states, at least {100 * depths_a.min():.1f} cm inside "
                       f"otherwise; feet at most {1000 * stability['max_foot_drift']:.1f} mm from their fixed positions")
    if reason:
        details.append(f"first problem: {reason}")
    if not valid:
        status, word = EXIT_INVALID, "INVALID"
    elif not checker.constraint.recheckable or not rechecked:
        status, word = EXIT_CANNOT, "CANNOT RECHECK the constraint (user type)"
    elif not checker.files.verified:
        status, word = EXIT_CANNOT, "UNVERIFIED (the robot files differ from the file's; see the warning)"
    else:
        status, word = EXIT_VALID, "VALID"
    line = (f"{file}: {len(path)} waypoints, {count:,} states checked every {resolution:g}; "
            f"{checker.constraint.use(worst, violations)}, {collisions} in collision, {outside} outside the limits: "
            f"{word}")
    return {"status": status, "line": line, "details": details, "valid": valid, "reason": reason, "worst": worst,
            "violations": violations, "collisions": collisions, "outside": outside, "states": count,
            "resolution": resolution, "meta": meta, "path": path, "stability": stability}


def bench_checks(folder: Path, urdf: str | None, srdf: str | None, resolution: float | None):
    """One report per solved run of a ``manifoldgen bench plan`` folder, then one counting the unsolved runs (cannot
    recheck where no run was solved)."""
    try:
        meta = json.loads((folder / "problem.json").read_text())
        records = [json.loads(line) for line in (folder / "runs.jsonl").read_text().splitlines() if line.strip()]
    except (OSError, ValueError) as exc:
        reason = f"not a readable bench folder (problem.json and runs.jsonl): {exc}"
        yield {"status": EXIT_CANNOT, "details": [], "line": f"{folder}: CANNOT RECHECK: {reason}"}
        return
    try:
        path_kind(meta)
        resolution = path_resolution(meta, resolution, "problem.json")
    except CannotRecheck as exc:
        yield {"status": EXIT_CANNOT, "details": [], "line": f"{folder}: CANNOT RECHECK: {exc}"}
        return
    unsolved = 0
    for record in records:
        if not record.get("solved"):
            unsolved += 1
            continue
        name = f"{folder} {record.get('method')} run {record.get('run')}"
        yield outside_check(name, urdf, srdf, resolution, content=(meta, np.asarray(record.get("path", []), float)),
                            near=folder)
    if unsolved == len(records):  # nothing rechecked: exit 0 would vouch for nothing
        yield {"status": EXIT_CANNOT, "details": [], "line": f"{folder}: CANNOT RECHECK: no solved run to recheck "
               f"({len(records)} runs in runs.jsonl, none solved)"}
        return
    yield {"status": EXIT_VALID, "details": [],
           "line": f"{folder}: {len(records) - unsolved} solved runs rechecked above, {unsolved} unsolved (no path)"}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Recheck manifoldgen path files (pinocchio + coal only).",
                                     epilog="exit status: 0 valid, 1 invalid, 2 usage, 3 could not recheck")
    parser.add_argument("files", nargs="+", help="path .npz files written by `manifoldgen plan`, or folders "
                                                 "written by `manifoldgen bench plan`")
    parser.add_argument("--urdf", help="the robot's URDF, when the recorded one cannot be found")
    parser.add_argument("--srdf", help="the robot's SRDF (disabled collision pairs)")
    parser.add_argument("--resolution", type=float,
                        help="state spacing along segments (default: the file's meta.validation.resolution)")
    args = parser.parse_args(argv)
    return print_reports(report for path in args.files for report in (
        bench_checks(Path(path), args.urdf, args.srdf, args.resolution) if Path(path).is_dir()
        else [outside_check(path, args.urdf, args.srdf, args.resolution)]))


if __name__ == "__main__":
    sys.exit(main())
