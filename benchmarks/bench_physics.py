"""The physics check over a folder of path files: how many stay upright, how much they tilt and slip.

    python benchmarks/bench_physics.py FOLDER [--duration-scale 1.0] [-o physics.jsonl]
    python benchmarks/bench_physics.py --calibrate OUT_FOLDER

Every ``*.npz`` path file of a floating-base robot in FOLDER is executed in MuJoCo (``manifoldgen.physics``);
prints one line per path, then the fraction upright / stable / fallen, tilt, slip and drift statistics, wall
and CPU time. ``-o`` writes every result as a JSON line.

``--calibrate`` first writes, into OUT_FOLDER, centauro paths whose last state has the centre of mass a chosen
distance inside or outside the support polygon (a stance with the front legs turned in, the base pushed forwards
or backwards with the feet kept where they stand), then checks them: the verdict should flip where the CoM leaves
the polygon. Each row gives the CoM's signed distance outside the polygon at the end of the path (negative: inside).
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np

from manifoldgen.io import load_npz, save_npz
from manifoldgen.physics import PhysicsSettings, check_path_file
from manifoldgen.runtime import set_threads

FEET = ["wheel_1", "wheel_2", "wheel_3", "wheel_4"]
LEGS = [f"{j}_{i}" for i in range(1, 5) for j in ("hip_yaw", "hip_pitch", "knee_pitch", "ankle_pitch")]
# centauro's SRDF stance with the front legs turned in: the CoM 0.076 m inside the front edge (as tests/test_physics.py)
HOME = [0.0, 0.0, 0.687, 0.0, 0.0, 0.0,
        -1.746874, -1.25409, -1.55576, -0.301666, 1.746874, 1.25409, 1.55576, 0.301666,
        0.746874, 1.25409, 1.55576, 0.301667, -0.746874, -1.25409, -1.55576, -0.301667]
PUSHES = [-0.10, -0.05, 0.0, 0.02, 0.04, 0.06, 0.08, 0.10, 0.12, 0.15, 0.20, 0.30]  # base x at the end, m


def calibration_paths(folder: Path) -> dict[Path, float]:
    """Write one path per push into ``folder``; returns path file -> CoM distance outside the polygon at its end."""
    from manifoldgen.constraints.base import ConstraintSet
    from manifoldgen.constraints.joint_linear import JointLinearConstraint
    from manifoldgen.constraints.projection import project
    from manifoldgen.robot import Robot
    from manifoldgen.tasks import load_task_file

    folder.mkdir(parents=True, exist_ok=True)
    robot = Robot.load("centauro", LEGS, floating_base=True)
    feet = [robot.frame_pose(np.array(HOME), f)[0][0].tolist() for f in FEET]
    task_file = folder / "calibration-task.toml"
    task_file.write_text(f"""name = "physics-calibration"
robot = "centauro"
floating_base = true
base_bounds = [[-0.5, -0.5, 0.4], [0.5, 0.5, 1.0]]
group = {json.dumps(["base_x", "base_y", "base_z", "base_yaw", "base_pitch", "base_roll", *LEGS])}
home = {json.dumps(HOME)}
home_condition = [0.687]
[[constraints]]
type = "balance"
feet = {json.dumps(FEET)}
foot_positions = {json.dumps(feet)}
base_frame = "pelvis"
values = [[0.687]]
margin = 0.0
""")
    task = load_task_file(task_file)
    base_x = np.eye(robot.n)[[0]]  # base x set; its pitch follows (legs that pitch roll their wheels a little)
    feet_and_base = ConstraintSet([task.constraint, JointLinearConstraint(robot, base_x, [[0.0]])])
    out = {}
    for i, push in enumerate(PUSHES):
        states = [task.home]
        for x in np.linspace(0.0, push, 7)[1:]:
            res = project(feet_and_base, states[-1], [0.687, x])
            if not res.converged[0]:
                raise RuntimeError(f"projection failed pushing the base to x = {x:.3f} m")
            states.append(res.q[0])
        file = folder / f"push{i:02d}{push:+.2f}.npz"
        save_npz(file, {**task.meta(), "kind": "path", "calibration_push_m": push}, path=np.array(states))
        out[file] = float(task.constraint.inequality(states[-1], [0.687]).max())
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("folder", type=Path, nargs="?")
    parser.add_argument("--calibrate", type=Path, help="write centauro calibration paths here and check them")
    parser.add_argument("--duration-scale", type=float, default=1.0, help="multiplies the motion's duration")
    parser.add_argument("--hold", type=float, default=1.0, help="seconds holding the last state")
    parser.add_argument("-o", "--output", type=Path, help="JSON lines, one result per path")
    args = parser.parse_args()
    set_threads()  # as every command: torch's and numpy's BLAS threads sized for this machine
    if (args.folder is None) == (args.calibrate is None):
        parser.error("give a FOLDER of path files, or --calibrate OUT_FOLDER")
    pace = PhysicsSettings()
    scale = args.duration_scale  # speeds / scale, accelerations / scale^2: every segment lasts scale times as long
    settings = PhysicsSettings(seconds_per_rad=pace.seconds_per_rad * scale, seconds_per_m=pace.seconds_per_m * scale,
                               max_acceleration_rad=pace.max_acceleration_rad / scale ** 2,
                               max_acceleration_m=pace.max_acceleration_m / scale ** 2, hold_s=args.hold)
    outside = calibration_paths(args.calibrate) if args.calibrate else {}
    files = sorted(outside) if outside else sorted(args.folder.glob("*.npz"))
    results, wall, cpu = [], time.perf_counter(), time.process_time()
    for file in files:
        meta, _ = load_npz(file, ("path",))
        if not meta.get("floating_base"):
            print(f"{file.name}: skipped (fixed base)")
            continue
        r = check_path_file(file, settings)
        results.append(r)
        com = f"CoM {outside[file] * 100:+5.1f} cm outside | " if outside else ""
        print(f"{file.name}: {com}{'FELL' if r.fell else 'upright' if r.upright else 'tilted'} | tilt "
              f"{r.max_tilt_deg:5.2f} deg | slip {r.max_slip_m * 1000:5.1f} mm | drift {r.base_drift_m * 1000:6.1f} mm "
              f"| tracking {r.max_tracking_error_rad:.4f} rad | {r.simulated_s:.2f} s simulated, {r.cpu_s:.2f} s CPU")
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    if args.output:
        args.output.write_text("".join(json.dumps(r.to_dict()) + "\n" for r in results))
    if not results:
        print("no floating-base path files")
        return
    tilt, slip, drift = (np.array([getattr(r, k) for r in results]) for k in ("max_tilt_deg", "max_slip_m",
                                                                               "base_drift_m"))
    print(f"{len(results)} paths: upright {np.mean([r.upright for r in results]):.0%}, stable (slip <= "
          f"{settings.slip_threshold_m} m) {np.mean([r.stable for r in results]):.0%}, fell "
          f"{np.mean([r.fell for r in results]):.0%} | tilt median {np.median(tilt):.2f} max {tilt.max():.2f} deg | "
          f"slip median {np.median(slip) * 1000:.1f} max {slip.max() * 1000:.1f} mm | drift median "
          f"{np.median(drift) * 1000:.1f} max {drift.max() * 1000:.1f} mm | {wall:.1f} s wall, {cpu:.1f} s CPU "
          f"checking")


if __name__ == "__main__":
    main()
