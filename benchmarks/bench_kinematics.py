"""Cost per call of the numpy forward kinematics a Python constraint calls: ``Robot.frame_pose`` and ``Robot.com``.

    python benchmarks/bench_kinematics.py [--robot xarm7] [--frame link_eef] [--batches 1 8 64 512 2048]
    python benchmarks/bench_kinematics.py --robot talos --floating --frame left_sole_link --com --pinocchio

For each batch size B, random configurations inside the limits (seed 0), calls repeated until 0.3 s of CPU:
prints CPU and wall microseconds per call and CPU microseconds per row, then the CPU time of the whole run and
the load average (the machine may be shared). For a before/after curve, run it at each commit (an editable
install's import hook comes before ``PYTHONPATH``: another checkout's ``src`` there is not what gets imported).
``--pinocchio`` also times the alternative of a pinocchio call per row on a cached model and data
(``Robot.to_pinocchio``, then ``forwardKinematics`` + ``updateFramePlacement``, or ``centerOfMass``).
"""

import argparse
import os
import time

import numpy as np
import pinocchio as pin

from manifoldgen.robot import Robot
from manifoldgen.runtime import set_threads

parser = argparse.ArgumentParser()
parser.add_argument("--robot", default="xarm7")
parser.add_argument("--joints", nargs="*", default=None, help="planning group (default: every movable joint)")
parser.add_argument("--floating", action="store_true", help="load with a floating base")
parser.add_argument("--frame", default="link_eef")
parser.add_argument("--com", action="store_true", help="also time Robot.com")
parser.add_argument("--pinocchio", action="store_true", help="also time a pinocchio call per row")
parser.add_argument("--batches", type=int, nargs="+", default=[1, 8, 64, 512, 2048])
parser.add_argument("--budget", type=float, default=0.3, help="CPU seconds per measurement")
args = parser.parse_args()
set_threads()  # as every command: torch's and numpy's BLAS threads sized for this machine


def per_call(fn, q) -> tuple[float, float]:
    """(CPU, wall) microseconds per call of ``fn(q)``, calls repeated until ``args.budget`` CPU seconds."""
    fn(q)  # warm caches (the robot's tables, pinocchio's data)
    calls, cpu0, wall0 = 0, time.process_time(), time.perf_counter()
    while (cpu := time.process_time() - cpu0) < args.budget:
        for _ in range(10):
            fn(q)
        calls += 10
    return 1e6 * cpu / calls, 1e6 * (time.perf_counter() - wall0) / calls


began_cpu, began_wall = time.process_time(), time.perf_counter()
robot = Robot.load(args.robot, args.joints, floating_base=args.floating)
rng = np.random.default_rng(0)
data, fid = robot.model.createData(), robot.frame_id(args.frame)


def pinocchio_pose(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position (B, 3) and rotation (B, 3, 3) of the frame, one pinocchio call per row."""
    p, R = np.empty((len(q), 3)), np.empty((len(q), 3, 3))
    for i, full in enumerate(robot.to_pinocchio(q)):
        pin.forwardKinematics(robot.model, data, full)
        placement = pin.updateFramePlacement(robot.model, data, fid)
        p[i], R[i] = placement.translation, placement.rotation
    return p, R


def pinocchio_com(q: np.ndarray) -> np.ndarray:
    """(B, 3) centre of mass, one pinocchio call per row."""
    return np.array([pin.centerOfMass(robot.model, data, full) for full in robot.to_pinocchio(q)])


kinds = [("frame_pose", lambda q: robot.frame_pose(q, args.frame))]
kinds += [("pinocchio per row: frame pose", pinocchio_pose)] if args.pinocchio else []
kinds += [("com", robot.com)] if args.com else []
kinds += [("pinocchio per row: com", pinocchio_com)] if args.com and args.pinocchio else []
print(f"{args.robot} ({robot.n} coordinates{', floating base' if args.floating else ''}), frame {args.frame}")
print("| call | batch | µs CPU a call | µs wall a call | µs CPU a row |")
print("|---|---|---|---|---|")
for name, fn in kinds:
    for batch in args.batches:
        q = robot.sample_uniform(batch, rng)
        cpu, wall = per_call(fn, q)
        print(f"| {name} | {batch} | {cpu:.1f} | {wall:.1f} | {cpu / batch:.2f} |", flush=True)
print(f"({time.perf_counter() - began_wall:.1f} s wall, {time.process_time() - began_cpu:.1f} s CPU, "
      f"load average {os.getloadavg()[0]:.2f})")
