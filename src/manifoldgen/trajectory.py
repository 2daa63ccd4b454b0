"""Time-parameterised trajectories of a path file: TOPP-RA within joint velocity and acceleration limits.

The path's straight segments are densified every ``resolution`` rad (the validation spacing) and a
C2 cubic spline is fitted through those states: it strays at most 6e-4 rad from the validated
segments on the panda, pr2 and centauro paths tried. TOPP-RA (the ``toppra`` package) finds the
fastest timing within the velocity limits (the URDF's, times ``vel_scale``) and the acceleration
limits (``ACC_PER_VELOCITY`` x the velocity limit, times ``acc_scale``: URDFs give none); both scales
range from ``MIN_SCALE`` to 1. TOPP-RA enforces its limits at grid points only, so the time is then
stretched uniformly until every written sample is within them. Where the spline bulges past a joint
limit at a corner of the path, the sample is clipped to the limit (the amount is reported). Every
written state is rechecked by the constrained space: limits, the constraint's tolerance and collisions
with the scene the path file records.

The file follows ROS ``trajectory_msgs/JointTrajectory``: ``joint_names`` and ``points`` with
``positions``, ``velocities``, ``accelerations`` and ``time_from_start`` (``sec``, ``nanosec``), besides
``generator`` ("manifoldgen") and ``manifoldgen`` (how it was made).
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from manifoldgen.errors import ManifoldgenError, file_reader, require
from manifoldgen.io import CSV_HEADER, GENERATOR, atomic_write_text, check_output_path
from manifoldgen.robot import BASE_JOINTS, Robot
from manifoldgen.space import ConstrainedSpace, ValidationSettings, densify

if TYPE_CHECKING:
    from manifoldgen.tasks import Task

ACC_PER_VELOCITY = 2.0  # reference acceleration limit per unit of velocity limit (1/s): full speed in 0.5 s
BASE_VELOCITY = 0.5  # m/s or rad/s for floating-base coordinates (no URDF joint)
GRID_PER_STATE = 2  # TOPP-RA grid points per densified state
STRETCH_STEPS = 20
DT_RANGE = (1e-4, 10.0)  # seconds between trajectory samples (inclusive)
MIN_SCALE = 1e-3  # the smallest --vel-scale and --acc-scale (smaller ones leave TOPP-RA without a timing)
MAX_STATES = 10_000_000  # trajectory samples one file may hold (refused before they are allocated)


@dataclass
class Trajectory:
    """Samples at ``time (T,)`` of ``positions``, ``velocities`` and ``accelerations`` (T, n) for
    ``joint_names``; ``info``: duration, path length, limits, scales and the recheck."""

    joint_names: list[str]
    time: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    info: dict

    def to_ros(self) -> dict:
        """A ``JointTrajectory``-shaped dict (ROS 2 time fields), with ``info`` under ``manifoldgen``."""
        sec = np.floor(self.time).astype(int)
        nanosec = np.minimum(np.round((self.time - sec) * 1e9).astype(int), 999_999_999)
        points = [{"positions": p.tolist(), "velocities": v.tolist(), "accelerations": a.tolist(),
                   "time_from_start": {"sec": int(s), "nanosec": int(ns)}}
                  for p, v, a, s, ns in zip(self.positions, self.velocities, self.accelerations, sec, nanosec)]
        return {"generator": GENERATOR, "kind": "trajectory", "joint_names": self.joint_names, "points": points,
                "manifoldgen": self.info}

    def save(self, out: str | Path) -> None:
        """Write ``.json`` (:meth:`to_ros`) or ``.csv`` (time, then each joint's position, velocity,
        acceleration columns), atomically."""
        out = check_output_path(out, kind="trajectory")
        if out.suffix.lower() == ".json":
            atomic_write_text(out, json.dumps(self.to_ros(), indent=1))
            return
        buffer = io.StringIO()
        writer = csv.writer(buffer)
        writer.writerow([CSV_HEADER.rstrip(",")] + [f"{j}.{kind}" for kind in ("position", "velocity", "acceleration")
                                               for j in self.joint_names])
        for row in np.column_stack([self.time, self.positions, self.velocities, self.accelerations]):
            writer.writerow([repr(float(x)) for x in row])
        atomic_write_text(out, buffer.getvalue())


def velocity_limits(robot: Robot) -> np.ndarray:
    """(n,) joint velocity limits from the URDF (``BASE_VELOCITY`` for floating-base coordinates)."""
    limits = []
    for name in robot.joints:
        if name in BASE_JOINTS:
            limits.append(BASE_VELOCITY)
            continue
        value = float(robot.model.velocityLimit[robot.model.joints[robot.model.getJointId(name)].idx_v])
        if not np.isfinite(value) or value <= 0:
            raise ManifoldgenError(f"the URDF of {robot.name} gives joint {name} no velocity limit; add "
                                   "<limit velocity=...> to it")
        limits.append(value)
    return np.array(limits)


def check_scale(value: float, what: str) -> float:
    """``value`` of ``what`` (--vel-scale, --acc-scale) when a fraction of the robot's limits from :data:`MIN_SCALE`
    to 1 (below it TOPP-RA may find no timing, or the trajectory too many states)."""
    if not (np.isfinite(value) and MIN_SCALE <= value <= 1):
        raise ManifoldgenError(f"{what} must be in (0, 1], at least {MIN_SCALE:g} (a fraction of the robot's limits), "
                               f"got {value}")
    return float(value)


def time_parameterize(path: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray, dt: float = 0.01,
                      resolution: float = ValidationSettings.resolution) -> tuple[np.ndarray, ...]:
    """Time ``path (K, n)`` within ``velocity (n,)`` and ``acceleration (n,)`` limits; returns
    ``time (T,)``, positions, velocities, accelerations ``(T, n)`` sampled at most ``dt`` apart, and
    the uniform time stretch applied after TOPP-RA."""
    toppra = require("toppra", "trajectory", "time parameterization (TOPP-RA)")

    states = densify(path, resolution)[0]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(states, axis=0), axis=1))])
    distinct = np.concatenate([[True], np.diff(s) > 1e-12])  # repeated waypoints
    states, s = states[distinct], s[distinct]
    if len(s) == 1:
        return np.zeros(1), states[:1], np.zeros_like(states[:1]), np.zeros_like(states[:1]), 1.0
    geometric = toppra.SplineInterpolator(s, states)
    grid = np.interp(np.linspace(0, len(s) - 1, GRID_PER_STATE * (len(s) - 1) + 1), np.arange(len(s)), s)
    solver = toppra.algorithm.TOPPRA([toppra.constraint.JointVelocityConstraint(velocity),
                                      toppra.constraint.JointAccelerationConstraint(acceleration)],
                                     geometric, gridpoints=grid, parametrizer="ParametrizeConstAccel")
    timed = solver.compute_trajectory()
    if timed is None:
        raise ManifoldgenError("TOPP-RA found no timing for this path (infeasible limits); check the limits (the "
                               "URDF's velocities, --vel-scale, --acc-scale)")
    stretch = 1.0
    for _ in range(STRETCH_STEPS):
        duration = timed.duration * stretch
        if duration / dt >= MAX_STATES:
            raise ManifoldgenError(f"the trajectory lasts {duration:.3g} s: {duration / dt:.3g} states at --dt {dt:g} "
                                   f"exceed {MAX_STATES:,}; raise --dt, --vel-scale or --acc-scale")
        t = np.linspace(0.0, duration, int(np.ceil(duration / dt)) + 1)
        qd, qdd = timed(t / stretch, 1) / stretch, timed(t / stretch, 2) / stretch ** 2
        ratio = max(np.abs(qd / velocity).max(), np.sqrt(np.abs(qdd / acceleration).max()))
        if ratio <= 1.0:
            return t, timed(t / stretch), qd, qdd, stretch
        stretch *= ratio * (1 + 1e-9)
    raise RuntimeError(f"internal error: the trajectory still exceeds its limits by {ratio:.3g} after stretching")


@file_reader
def trajectory_of_file(path_file: str | Path, vel_scale: float = 1.0, acc_scale: float = 1.0,
                       dt: float = 0.01, *, task: Task | None = None, trust_code: bool = False) -> Trajectory:
    """The time-parameterised trajectory of a path file, every sample rechecked (``info["check"]``); ``task``,
    ``trust_code``: see :func:`~manifoldgen.tasks.task_from_meta`."""
    from manifoldgen.query import read_path_file
    from manifoldgen.scene import Scene

    vel_scale, acc_scale = check_scale(vel_scale, "--vel-scale"), check_scale(acc_scale, "--acc-scale")
    if not (np.isfinite(dt) and DT_RANGE[0] <= dt <= DT_RANGE[1]):
        raise ManifoldgenError(f"--dt must be from {DT_RANGE[0]:g} to {DT_RANGE[1]:g} seconds, got {dt}")
    meta, path, task = read_path_file(path_file, task, trust_code=trust_code)
    robot = task.robot
    urdf_velocity = velocity_limits(robot)
    velocity, acceleration = urdf_velocity * vel_scale, ACC_PER_VELOCITY * urdf_velocity * acc_scale
    t, q, qd, qdd, stretch = time_parameterize(path, velocity, acceleration, dt)
    clipped = np.clip(q, robot.lower, robot.upper)
    space = ConstrainedSpace(task.constraint, np.asarray(meta["condition"], float),
                             Scene.from_meta(meta).checker(robot))
    # a controller moves straight between samples: the dense check of that motion covers the samples too, so the
    # samples are counted one by one only when it fails
    motions = space.validate_path(clipped)
    valid = np.ones(len(t), bool) if motions.valid else space.valid(clipped)
    first = None if valid.all() else int(np.argmin(valid))
    worst = motions.worst_violation if motions.valid else float(space.violation(clipped).max())
    check = {"states": len(t), "valid": int(valid.sum()), "worst_violation": worst,
             "first_invalid": None if first is None else {"time": float(t[first]),
                                                          "problem": space.problem(clipped[first])},
             "first_invalid_motion": None if motions.valid or first is not None else {
                 "time": float(t[motions.segment]), "problem": motions.reason},
             "max_clip": float(np.abs(clipped - q).max()),
             "max_velocity_ratio": float(np.abs(qd / velocity).max()),
             "max_acceleration_ratio": float(np.abs(qdd / acceleration).max())}
    info = {"source": str(path_file), "robot": robot.name, "duration": float(t[-1]),
            "path_length": float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()), "waypoints": len(path),
            "vel_scale": vel_scale, "acc_scale": acc_scale, "dt": dt, "stretch_after_toppra": stretch,
            "velocity_limits": velocity.tolist(), "acceleration_limits": acceleration.tolist(), "check": check}
    return Trajectory(list(robot.joints), t, clipped, qd, qdd, info)
