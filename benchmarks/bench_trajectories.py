"""Shortened paths as trajectories: does every sample of the timed trajectory stay valid?

    python benchmarks/bench_trajectories.py [--scenes wall maze] [--seeds 20] [--time 10]

For each scene of the panda ``pose`` task and each seed, plans with the shipped CVAE, the path shortened within the
query (``smooth``: shortcuts, then the relaxation), writes the path file, time-parameterises it at full velocity and
acceleration scale (``manifoldgen trajectory``'s ``trajectory_of_file``) and counts the trajectories with a sample
that fails the constrained space's check (limits, constraint, collisions), naming the first such sample. A path that
passes the dense check can still clip an obstacle between two of its states; a trajectory's samples land there.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import manifoldgen as mg
from manifoldgen.trajectory import trajectory_of_file


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["wall", "maze"])
    parser.add_argument("--seeds", type=int, default=20, help="seeds 0 .. SEEDS-1 per scene")
    parser.add_argument("--time", type=float, default=10.0, help="each query's time limit (s)")
    args = parser.parse_args()
    task, model = mg.load_task("pose", robot="panda"), mg.load_model(mg.pretrained_model_dir())
    timed = invalid = 0
    with tempfile.TemporaryDirectory() as folder:
        for name in args.scenes:
            scene = mg.load_scene(task, name)
            for seed in range(args.seeds):
                sampler = mg.sampler(task, scene, model, seed=seed)
                result = mg.plan(task, scene, sampler=sampler, seed=seed, time_limit=args.time, smooth=True)
                if not result.solved:
                    print(f"{name} seed {seed}: not solved")
                    continue
                path_file = result.save(Path(folder) / f"{name}-{seed}.npz")
                check = trajectory_of_file(path_file).info["check"]
                timed += 1
                if check["valid"] < check["states"]:
                    invalid += 1
                    print(f"{name} seed {seed}: {check['states'] - check['valid']} of {check['states']} samples "
                          f"invalid, the first at {check['first_invalid']['time']:.2f} s: "
                          f"{check['first_invalid']['problem']}")
    print(f"{timed} trajectories of shortened paths ({', '.join(args.scenes)}, seeds 0-{args.seeds - 1}): "
          f"{invalid} with an invalid sample")


if __name__ == "__main__":
    main()
