"""The C++ OMPL Atlas baseline's RRT-Connect range on a balance reach: is the bench's default (0.6 rad) its best?

    python benchmarks/bench_atlas_range.py [--robot talos] [--seed 30] [--runs 30] [--ranges 0.3 0.45 0.6 0.9]
                                           [--ours cvae:OUT/talos-cvae,batch=64]

Runs ompl-native-atlas on the reach's query with seeds seed .. seed + runs - 1 (the talos bench's settings: sphere
broad phase, OMPL's delta 0.05) at each range, and with --ours our RRT-Connect with that sampler (the task file's
planner settings and the talos bench's: pool 0, pool_batch 32, resolution 0.02, spheres), all interleaved per seed.
Prints per method the runs solved and the median CPU of the solved ones, counted as the bench counts it (Atlas: the
program's CPU plus our dense check of its paths), and ours against each. Our planner's range is chosen on held-out
seeds with `manifoldgen bench plan ... --seed 30 --set range=R` (README, "Certified constraints"); this gives the
baseline the same chance.
"""

import argparse
import time

import numpy as np

from manifoldgen.bench.planning import Experiment, Method, build
from manifoldgen.runtime import set_threads


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="talos")
    parser.add_argument("--seed", type=int, default=30)
    parser.add_argument("--runs", type=int, default=30)
    parser.add_argument("--ranges", type=float, nargs="+", default=[0.3, 0.45, 0.6, 0.9])
    parser.add_argument("--ours", help="our sampler spec, e.g. cvae:OUT/talos-cvae,batch=64 (default: Atlas only)")
    args = parser.parse_args()
    set_threads()  # as the bench's workers: one thread, no idle threads spinning on our CPU clock
    experiment = Experiment("reach", task="balance", robot=args.robot, time_limit=30.0, resolution=0.05,
                            planner_settings={"spheres": True, "pool": 0, "pool_batch": 32, "resolution": 0.02})
    atlas = Method.parse("atlas-c++=ompl-native-atlas")
    methods = [(f"C++ Atlas, range {r:g}", atlas, r) for r in args.ranges]
    if args.ours:
        methods.insert(0, ("ours", Method.parse(f"ours=rrtconnect@{args.ours}"), None))
    cpu = {label: [] for label, _, _ in methods}
    for seed in range(args.seed, args.seed + args.runs):
        for label, method, r in methods:
            planner, scene, _ = build(experiment, method, seed)
            if r is not None:
                planner.settings.range = r
            began = time.process_time()
            result = planner.solve(scene.start, scene.goal, experiment.time_limit)
            used = time.process_time() - began
            if result.solved:
                extras = result.extras
                cpu[label].append(extras["native_cpu_s"] + extras["dense_cpu_s"] if r is not None else used)
    print(f"balance {args.robot} reach, seeds {args.seed}-{args.seed + args.runs - 1}")
    print("| method | solved | median CPU, solved (s) | against ours |\n|---|---|---|---|")
    ours = np.median(cpu["ours"]) if args.ours and cpu["ours"] else None
    for label, _, _ in methods:
        median = np.median(cpu[label]) if cpu[label] else None
        ratio = f"{median / ours:.2f}x" if median is not None and ours else "-"
        print(f"| {label} | {len(cpu[label])}/{args.runs} | {'-' if median is None else f'{median:.4f}'} | {ratio} |")


if __name__ == "__main__":
    main()
