"""Outside checker for manifoldgen roadmap files: numpy, pinocchio and coal only.

A roadmap file (``manifoldgen plan --roadmap FILE``; see docs/file-formats.md) holds ``nodes (N, n)``,
``edges (E, 2)`` (node pairs), ``lengths (E,)`` and ``meta``: a path file's task, query condition and scene, plus
``resolution`` (the spacing its edges were checked at) and ``scene_sha256``. Every edge is rechecked as a path of
two waypoints by check_path.py's rules (states every ``meta["resolution"]`` along it, Euclidean in the group's
coordinates, both ends included: the constraint with every built-in type recomputed with pinocchio, the
inequalities, the joint limits, self-collision, the obstacles and the held object), a node without an edge as one
state; each recorded length is compared with its nodes' distance, and ``scene_sha256`` with the recorded objects.

    python examples/check_roadmap.py r.npz [more.npz ...] [--urdf PATH] [--srdf PATH] [--resolution R]
    -> r.npz: 55 nodes, 60 edges, 4,412 states checked every 0.005; 0 edges invalid (worst constraint use 0.61
       of tolerance, 0 states violating the constraint, 0 in collision, 0 outside the limits): VALID

Exit status: 0 every roadmap valid; 1 some edge invalid; 2 bad usage; 3 could not recheck (a user constraint type
``module:Class``, the robot not found or not the file's, an unreadable file or not a roadmap, or one manifoldgen does
not write: another format, a robot_identity not the robot files', malformed arrays or edges, an absurd resolution).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from check_path import checked_resolution, outside_check, segment_steps, within_budget  # noqa: E402
from recheck import (EXIT_CANNOT, EXIT_INVALID, EXIT_VALID, CannotRecheck, Checker, RobotFiles,  # noqa: E402
                     exit_status, print_reports, read_npz, sha256)

LENGTH_TOLERANCE = 1e-9  # rad: a recorded edge length against its nodes' distance, as manifoldgen reads it
FORMAT_VERSION = 1  # the roadmap format docs/file-formats.md describes
REMAKE = "remake the file with `manifoldgen plan --roadmap`"


def read_roadmap(file) -> tuple[dict, np.ndarray, np.ndarray, np.ndarray]:
    """``meta``, ``nodes (N, n)``, ``edges (E, 2)`` int and ``lengths (E,)`` of a roadmap file, its kind, format,
    array types and shapes checked, and every edge two distinct nodes, lower first, each pair once."""
    meta, arrays = read_npz(file, ("nodes", "edges", "lengths"))
    if meta.get("kind") != "roadmap":
        raise CannotRecheck(f"meta 'kind' is {meta.get('kind')!r}, not 'roadmap' (check a path with check_path.py)")
    if meta.get("format_version") != FORMAT_VERSION:
        raise CannotRecheck(f"meta 'format_version' is {meta.get('format_version')!r}, not {FORMAT_VERSION} (the "
                            f"roadmap format this checker reads); {REMAKE}")
    nodes, edges, lengths = arrays["nodes"], arrays["edges"], arrays["lengths"]
    n = len(meta["joints"])
    if nodes.dtype != np.float64 or nodes.ndim != 2 or nodes.shape[1] != n:
        raise CannotRecheck(f"nodes are {nodes.dtype} {nodes.shape}, the format stores float64 (N, {n}) for the "
                            f"file's joints; {REMAKE}")
    if edges.dtype.kind not in "iu" or edges.ndim != 2 or edges.shape[1] != 2:
        raise CannotRecheck(f"edges are {edges.dtype} {edges.shape}, the format stores (E, 2) integer node indices; "
                            f"{REMAKE}")
    if lengths.dtype != np.float64 or lengths.shape != (len(edges),):
        raise CannotRecheck(f"lengths are {lengths.dtype} {lengths.shape}, the format stores float64 ({len(edges)},), "
                            f"one per edge; {REMAKE}")
    first = {}
    for e, (a, b) in enumerate(edges.tolist()):
        if not (0 <= a < len(nodes) and 0 <= b < len(nodes)):
            why = f"names a node outside 0..{len(nodes) - 1}"
        elif a == b:
            why = f"joins node {a} to itself"
        elif a > b:
            why = "has its higher node first (the format stores each edge lower node first)"
        elif (a, b) in first:
            why = f"repeats edge {first[a, b]}"
        else:
            first[a, b] = e
            continue
        raise CannotRecheck(f"edge {e} [{a}, {b}] {why}; {REMAKE}")
    return meta, nodes, edges.astype(int), lengths


def identity_problem(identity, files: RobotFiles) -> str | None:
    """Why meta ``robot_identity`` is not the robot files found (URDF and SRDF by sha256), or None."""
    if not isinstance(identity, dict) or not identity.get("urdf_sha256"):
        return f"meta 'robot_identity' {identity!r:.80} has no urdf_sha256; {REMAKE}"
    for key, path in (("urdf_sha256", files.urdf), ("srdf_sha256", files.srdf)):
        found = sha256(path) if path is not None else None
        if identity.get(key) != found:
            return (f"meta robot_identity {key} {str(identity.get(key))[:12]} is not that of the robot files found "
                    f"({path or 'no SRDF'}: {str(found)[:12]}); pass the file's robot with --urdf/--srdf or {REMAKE}")
    return None


def roadmap_check(file, urdf: str | None = None, srdf: str | None = None, resolution: float | None = None) -> dict:
    """Recheck one roadmap file. Returns ``status`` (exit code), ``line`` (verdict), ``details``, ``valid``,
    ``reason`` (the first problem), ``invalid_edges`` (indices), ``worst`` (max |F_i| / tol_i over the states),
    ``violations``, ``collisions``, ``outside`` (states), ``states``, ``resolution``."""
    try:
        meta, nodes, edges, lengths = read_roadmap(file)
        resolution = (checked_resolution(meta.get("resolution"), "meta resolution") if resolution is None else
                      checked_resolution(resolution, "--resolution"))
        pieces = [(f"edge {e} (nodes {a}-{b})", nodes[[a, b]], e) for e, (a, b) in enumerate(edges)]
        pieces += [(f"node {i} (no edge)", nodes[[i]], -1) for i in sorted(set(range(len(nodes))) - set(edges.ravel()))]
        steps = segment_steps(np.linalg.norm(nodes[edges[:, 1]] - nodes[edges[:, 0]], axis=1), resolution)
        within_budget(steps.sum() + len(pieces), resolution)  # each edge's states and its last node; lone nodes
        y = np.asarray(meta.get("condition") or [], float).reshape(-1)
        checker = Checker(meta, len(y), scene=meta.get("scene") or [], urdf=urdf, srdf=srdf, near=Path(file).parent)
        problem = identity_problem(meta.get("robot_identity"), checker.files)
        if problem:
            raise CannotRecheck(problem)
    except CannotRecheck as exc:
        return {"status": EXIT_CANNOT, "details": [], "valid": False, "reason": str(exc), "invalid_edges": [],
                "line": f"{file}: CANNOT RECHECK: {exc}"}
    details = [f"note: {note}" for note in checker.notes]
    details.append(f"note: collision pairs: {checker.collisions.self_pairs} self, {checker.collisions.obstacles} "
                   f"obstacle(s), {checker.collisions.tools} held object(s)")
    problems, invalid, statuses = [], [], []
    objects = json.dumps(meta.get("scene") or [], sort_keys=True, separators=(",", ":"))
    if hashlib.sha256(objects.encode()).hexdigest() != meta.get("scene_sha256"):
        problems.append("meta 'scene_sha256' is not the sha256 of the recorded scene's objects (the file was edited)")
    worst, violations, collisions, outside, states = 0.0, 0, 0, 0, 0
    for name, path, e in pieces:
        report = outside_check(f"{file} {name}", resolution=resolution, content=(meta, path), checker=checker)
        statuses.append(report["status"])
        worst = max(worst, report["worst"])
        violations, collisions = violations + report["violations"], collisions + report["collisions"]
        outside, states = outside + report["outside"], states + report["states"]
        distance = float(np.linalg.norm(path[-1] - path[0]))
        if e >= 0 and not abs(lengths[e] - distance) <= LENGTH_TOLERANCE:
            report["reason"] = report["reason"] or f"recorded length {lengths[e]:g} is not its nodes' distance " \
                f"{distance:g}"
        if report["reason"]:
            problems.append(f"{name}: {report['reason']}")
            invalid += [e] if e >= 0 else []
    valid = not problems
    if problems:
        details.append(f"first problem: {problems[0]}")
    user = checker.constraint.user_types
    if not valid:
        status, word = EXIT_INVALID, "INVALID"
    elif exit_status(statuses) == EXIT_CANNOT:
        status, word = EXIT_CANNOT, ("CANNOT RECHECK the constraint (user type)" if user else
                                     "UNVERIFIED (the robot files differ from the file's; see the warning)")
    else:
        status, word = EXIT_VALID, "VALID"
    line = (f"{file}: {len(nodes)} nodes, {len(edges)} edges, {states:,} states checked every {resolution:g}; "
            f"{len(invalid)} edges invalid ({checker.constraint.use(worst, violations)}, {collisions} in collision, "
            f"{outside} outside the limits): {word}")
    return {"status": status, "line": line, "details": details, "valid": valid, "reason": problems[0] if problems
            else "", "invalid_edges": invalid, "worst": worst, "violations": violations,
            "collisions": collisions, "outside": outside, "states": states, "resolution": resolution}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Recheck manifoldgen roadmap files (pinocchio + coal only).",
                                     epilog="exit status: 0 valid, 1 invalid, 2 usage, 3 could not recheck")
    parser.add_argument("files", nargs="+", help="roadmap .npz files written by `manifoldgen plan --roadmap`")
    parser.add_argument("--urdf", help="the robot's URDF, when the recorded one cannot be found")
    parser.add_argument("--srdf", help="the robot's SRDF (disabled collision pairs)")
    parser.add_argument("--resolution", type=float,
                        help="state spacing along edges (default: the file's meta.resolution)")
    args = parser.parse_args(argv)
    return print_reports(roadmap_check(path, args.urdf, args.srdf, args.resolution) for path in args.files)


if __name__ == "__main__":
    sys.exit(main())
