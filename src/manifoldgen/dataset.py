"""The dataset container and its ``.npz`` file: configurations ``q (N, n) float64`` satisfying a constraint at
conditions ``y (N, k) float64``, and ``meta`` (a JSON string in the file) naming the robot, joints, constraint
and task they were made for (see :meth:`manifoldgen.tasks.Task.meta`; :mod:`manifoldgen.data` collects them)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from manifoldgen.errors import ManifoldgenError, did_you_mean, differences, file_reader, short
from manifoldgen.io import check_output_path, load_npz, save_npz
from manifoldgen.json_values import finite, number, numbers, text, texts, whole
from manifoldgen.runtime import MAX_SEED

FORMAT_VERSION = 2  # 2: meta["task"] holds the full task spec
TASK_KEYS = ("task", "robot", "joints", "locked", "floating_base", "constraint", "tolerance", "condition")
META_KEYS = ("format_version", *TASK_KEYS, "seed", "per_condition", "method", "near_home", "anchors", "scenes",
             "coverage",  # a dataset's; a sample file's besides:
             "dataset_seed", "rows", "refine", "generated_by", "raw_valid_rate", "refined_valid_rate")
# The keys of meta["task"]: those manifoldgen.tasks.Task.spec writes (a layer above this one; a test holds them equal).
TASK_SPEC_KEYS = ("name", "description", "robot", "robot_source", "srdf_source", "group", "floating_base",
                  "base_bounds", "locked", "constraint", "home", "home_condition", "task_file", "attached", "planner")
MAX_NEAR_HOME = 10.0  # rad: the widest spread of seeds around the task home that collect takes (near_home)


@dataclass
class Dataset:
    """Configurations ``q (N, n)`` satisfying the constraint at conditions ``y (N, k)``."""

    q: np.ndarray
    y: np.ndarray
    meta: dict

    def __len__(self) -> int:
        return len(self.q)

    def save(self, path: str | Path) -> None:
        """Write the file (atomic); what :meth:`load` would refuse (rows with NaN, q and y of different lengths,
        a meta without its task) is refused instead, and nothing written."""
        _check(np.asarray(self.q), np.asarray(self.y), self.meta, f"{path} (not written)")
        kind = "samples" if "generated_by" in self.meta else "dataset"
        save_npz(check_output_path(path, suffixes=(".npz",), kind=kind), self.meta, q=self.q, y=self.y)

    @classmethod
    @file_reader
    def load(cls, path: str | Path) -> Dataset:
        """Read and validate a dataset file (clear errors for truncated or foreign files)."""
        meta, arrays = load_npz(path, (), "dataset")
        missing = [key for key in ("q", "y") if key not in arrays]
        if missing:
            kind = meta.get("kind") if meta.get("kind") in ("path", "roadmap") else None
            what = f"a {kind} file, not a dataset" if kind else f"not a dataset (no {' or '.join(missing)} array)"
            raise ManifoldgenError(f"{path} is {what}: give a dataset written by `manifoldgen collect`")
        extra = sorted(set(arrays) - {"q", "y"})
        if extra:
            raise ManifoldgenError(f"{path}: unknown array '{extra[0]}' beside q and y; the file was edited: "
                                   "collect it again")
        _check(arrays["q"], arrays["y"], meta, str(path))
        return cls(np.asarray(arrays["q"], float), np.asarray(arrays["y"], float), meta)

    def summary(self) -> dict:
        values, counts = np.unique(self.y, axis=0, return_counts=True)
        return {"rows": len(self), "robot": self.meta["robot"], "joints": len(self.meta["joints"]),
                "conditions": {json.dumps(v.tolist()): int(c) for v, c in zip(values, counts)}}


def _check(q: np.ndarray, y: np.ndarray, meta: dict, where: str) -> None:
    """Refuse rows ``q (N, n)`` and ``y (N, k)`` with ``meta`` that no reader takes: arrays not of float64 numbers,
    shapes that disagree, NaN, a meta without what a dataset's holds (:func:`check_meta`). ``where``: the file."""
    if any(a.dtype.kind not in "fiu" for a in (q, y)):
        raise ManifoldgenError(f"{where}: q and y must be arrays of numbers, got {q.dtype} and {y.dtype}; "
                               "regenerate the file")
    narrow = next((name for name, a in (("q", q), ("y", y)) if a.dtype.kind == "f" and a.dtype.itemsize < 8), None)
    if narrow is not None:
        raise ManifoldgenError(f"{where}: {narrow} is {(q if narrow == 'q' else y).dtype}, which rounds rows off the "
                               "constraint and past the joint limits; store q and y as float64 (what collect writes)")
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(y))):
        raise ManifoldgenError(f"{where}: contains NaN or infinite values; recollect it")
    if not isinstance(meta, dict):
        raise ManifoldgenError(f"{where}: meta must be a JSON object; not a manifoldgen dataset")
    for key in ("format_version", "robot", "joints", "constraint"):
        if key not in meta:
            raise ManifoldgenError(f"{where}: meta lacks '{key}'; not a manifoldgen dataset")
    if meta["format_version"] != FORMAT_VERSION:
        raise ManifoldgenError(f"{where}: dataset format {meta['format_version']!r} is not the one this version "
                               f"reads ({FORMAT_VERSION}); collect it again")
    if not isinstance(meta["robot"], str) or not isinstance(meta["joints"], list) \
            or not all(isinstance(j, str) for j in meta["joints"]):
        raise ManifoldgenError(f"{where}: meta 'robot' must be a name and 'joints' a list of joint names; the file "
                               "was edited or is damaged: collect it again")
    if q.ndim != 2 or y.ndim != 2 or len(q) != len(y) or q.shape[1] != len(meta["joints"]):
        raise ManifoldgenError(f"{where}: inconsistent shapes q {q.shape}, y {y.shape} for "
                               f"{len(meta['joints'])} joints")
    check_meta(meta, y.shape[1], where)
    if "per_condition" in meta and "generated_by" not in meta:  # collect keeps that many rows at every value
        values, counts = np.unique(y, axis=0, return_counts=True)
        off = next((i for i, c in enumerate(counts) if c != meta["per_condition"]), None)
        if off is not None:
            raise ManifoldgenError(f"{where}: meta 'per_condition' {meta['per_condition']} but {counts[off]} rows at "
                                   f"condition {values[off].tolist()}; the file was edited: collect it again")


def check_meta(meta: dict, k: int, where: str) -> None:
    """Refuse a dataset's (or a model's) ``meta`` with an unknown key (in it or in its ``task``), a value of the wrong
    kind or range (:data:`KINDS`), copies of its task (``robot``, ``locked``, ``floating_base``, ``constraint``) that
    contradict ``meta["task"]``, a ``tolerance`` or ``condition`` (for ``k`` condition columns) of the wrong form, or
    ``scenes`` and ``anchors`` that no reader could use. ``where``: the file, for messages.
    (:func:`manifoldgen.provenance.check_task_copies` compares the rest once the task is built.)"""
    def bad(why: str) -> ManifoldgenError:
        return ManifoldgenError(f"{where}: meta {why}; the file was edited or is damaged: make it again")

    _check_known(meta, META_KEYS, "has", bad)
    for key, (fits, what) in KINDS.items():
        if key in meta and not fits(meta[key]):
            raise bad(f"'{key}' {short(meta[key])} must be {what}")
    task = meta.get("task")
    if task is not None:
        _check_known(task, TASK_SPEC_KEYS, "'task' has", bad)
        _check_task_spec(task, meta.get("joints"), k, bad)
        check_copies(meta, bad)
    tolerance = meta.get("tolerance", [1.0])
    if not (isinstance(tolerance, list) and tolerance and all(
            isinstance(t, (int, float)) and not isinstance(t, bool) and 0 < t < float("inf") for t in tolerance)):
        raise bad(f"'tolerance' {short(tolerance)} is not a list of positive numbers")
    condition = meta.get("condition", {"names": [""] * k, "units": [""] * k, "values": [[0.0] * k]})
    if not (isinstance(condition, dict) and set(condition) == {"names", "units", "values"}
            and all(isinstance(condition[key], list) and len(condition[key]) == k
                    and all(isinstance(v, str) for v in condition[key]) for key in ("names", "units"))
            and isinstance(condition["values"], list) and condition["values"]
            and all(numbers(row, k) for row in condition["values"])):
        raise bad(f"'condition' must hold names, units and value rows for y's {k} condition columns")
    _check_scenes(meta, k, bad)


def check_copies(meta: dict, bad) -> None:
    """Refuse (``bad(why)``: the error to raise) a top-level copy of the task's ``robot``, ``locked``,
    ``floating_base`` or ``constraint`` in ``meta`` (a dataset's, model's or path file's) that contradicts
    ``meta["task"]``."""
    task = meta.get("task")
    if not isinstance(task, dict):
        return
    identity = task.get("robot")
    copies = {"robot": identity.get("name") if isinstance(identity, dict) else identity,
              "locked": task.get("locked"), "floating_base": task.get("floating_base"),
              "constraint": task.get("constraint")}
    for key, value in copies.items():
        if key in meta and meta[key] != value:
            shown = (f"contradicts its task ({differences(meta[key], value, key, ('in the file', 'in the task'))})"
                     if isinstance(value, dict) else f"{short(meta[key])} contradicts its task's {short(value)}")
            raise bad(f"'{key}' {shown}")


def _check_task_spec(task: dict, joints, k: int, bad) -> None:
    """Refuse a task spec value of the wrong kind (:data:`TASK_SPEC_KINDS`), or a ``home`` without a number per
    joint (``joints``: the file's) or a ``home_condition`` without one per condition column (``k``)."""
    for key, (fits, what) in TASK_SPEC_KINDS.items():
        if key in task and not fits(task[key]):
            raise bad(f"task '{key}' {short(task[key])} must be {what}")
    n = len(joints) if isinstance(joints, list) else None
    if "home" in task and not numbers(task["home"], n):
        raise bad(f"task 'home' {short(task['home'])} must hold a number per joint ({n})")
    if "home_condition" in task and not numbers(task["home_condition"], k):
        raise bad(f"task 'home_condition' {short(task['home_condition'])} must hold a number per condition column "
                  f"({k})")


def _check_known(data: dict, known: tuple[str, ...], has: str, bad) -> None:
    """Refuse a key of ``data`` not in ``known``, naming the nearest known one (``has``: the message's subject)."""
    unknown = next((key for key in data if key not in known), None)
    if unknown is not None:
        raise bad(f"{has} an unknown key '{unknown}'{did_you_mean(unknown, known)}")


def _coverage(report) -> bool:
    """Whether ``report`` has the form :func:`manifoldgen.data.coverage` writes."""
    anchor_keys = {"label", "gap", "spacing", "missed"}
    return (isinstance(report, dict) and "modes" in report and set(report) <= {"modes", "anchors"}
            and isinstance(report["modes"], dict)
            and all(isinstance(shares, list) and all(number(s, 0, 1) for s in shares)
                    for shares in report["modes"].values())
            and isinstance(report.get("anchors", []), list)
            and all(isinstance(a, dict) and set(a) == anchor_keys and isinstance(a["label"], str)
                    and isinstance(a["missed"], bool) and number(a["gap"], 0) and number(a["spacing"], 0)
                    for a in report.get("anchors", [])))


KINDS = {  # meta key -> (whether its value fits, what it must be); the task's copies, scenes and anchors: apart
    "task": (lambda v: isinstance(v, dict), "an object (the task's spec)"),
    "seed": (lambda v: whole(v, 0, MAX_SEED), f"a whole number from 0 to {MAX_SEED}"),
    "per_condition": (lambda v: whole(v, 1), "a positive whole number (rows per condition value)"),
    "method": (lambda v: isinstance(v, str), "a string (how the rows were seeded)"),
    "near_home": (lambda v: number(v, 0, MAX_NEAR_HOME), f"a number from 0 to {MAX_NEAR_HOME:g} (rad)"),
    "coverage": (_coverage, 'an object {"modes": {condition: [shares]}, "anchors": [...]} as collect writes it'),
    "dataset_seed": (lambda v: v is None or whole(v, 0, MAX_SEED), f"null or a whole number from 0 to {MAX_SEED}"),
    "rows": (lambda v: v in ("raw", "refined"), '"raw" or "refined"'),
    "refine": (lambda v: whole(v, 0), "a whole number >= 0 (projection iterations)"),
    "generated_by": (lambda v: isinstance(v, dict) and set(v) == {"model", "source"} and all(
        isinstance(x, str) for x in v.values()), 'an object {"model": name, "source": path}'),
    "raw_valid_rate": (lambda v: number(v, 0, 1), "a share from 0 to 1"),
    "refined_valid_rate": (lambda v: number(v, 0, 1), "a share from 0 to 1"),
}


TASK_SPEC_KINDS = {  # meta["task"] key -> (whether its value fits, what it must be); home and its condition: apart
    "name": (text, "a string"),
    "description": (text, "a string"),
    "robot": (lambda v: isinstance(v, (str, dict)), "a robot name or its identity object"),
    "robot_source": (lambda v: v is None or text(v), "null or a string"),
    "srdf_source": (lambda v: v is None or text(v), "null or a path"),
    "group": (lambda v: texts(v) and len(v) > 0, "a list of joint names"),
    "floating_base": (lambda v: isinstance(v, bool), "true or false"),
    "base_bounds": (lambda v: isinstance(v, list) and len(v) == 2 and any(all(numbers(b, n) for b in v)
                                                                          for n in (3, 6)),
                    "[[x, y, z (yaw, pitch, roll) low], [the same high]]"),
    "locked": (lambda v: isinstance(v, dict) and all(finite(x) for x in v.values()),
               "an object joint -> value"),
    "constraint": (lambda v: isinstance(v, dict) and isinstance(v.get("type"), str), "an object with a 'type'"),
    "task_file": (lambda v: v is None or text(v), "null or a path"),
    "attached": (lambda v: isinstance(v, dict), "an object (the held object)"),
    "planner": (lambda v: isinstance(v, dict), "an object (planner settings)"),
}


def _check_scenes(meta: dict, k: int, bad) -> None:
    """Refuse ``scenes`` that are not a list of scene documents (objects; read whole by the race that plans them,
    :func:`manifoldgen.selection.select_model`, before any training) and ``anchors`` that are not labelled
    configurations (one number per joint) at conditions (``k`` numbers)."""
    scenes, anchors = meta.get("scenes", []), meta.get("anchors", [])
    if not isinstance(scenes, list) or not isinstance(anchors, list):
        raise bad("'scenes' and 'anchors' must be lists")
    if not all(isinstance(doc, dict) for doc in scenes):
        raise bad("'scenes' must hold scene documents (JSON objects)")
    joints = meta.get("joints")
    n = len(joints) if isinstance(joints, list) else None
    for i, anchor in enumerate(anchors):
        if not (isinstance(anchor, dict) and set(anchor) == {"label", "q", "condition"}
                and isinstance(anchor["label"], str) and numbers(anchor["q"], n) and numbers(anchor["condition"], k)):
            raise bad(f"anchors[{i}] must hold a 'label', its configuration 'q' (a number per joint: {n}) and its "
                      f"'condition' (a number per condition column: {k})")
