"""Wall scene (the paper's Table II), reduced: every method on the same query and seeds.

    python benchmarks/bench_wall.py [--runs 20] [--time 30] [--workers 2] [--out bench-wall]
                                    [--model DIR ...] [--methods SPEC ...]

Prints the Markdown table (success, mean/min/max/median time, path length, samples,
projections, worst violation) and each method's median speed-up over OMPL's
ProjectedStateSpace + RRTConnect. Default methods: see ``manifoldgen.bench.planning.
default_methods``; ``--model DIR ...`` replaces the shipped model by trained ones. The full paper
version is ``manifoldgen bench wall --runs 1000 --time 200 -o OUT``.
"""

import argparse

from manifoldgen.bench.planning import Experiment, default_baseline, default_methods, run_bench
from manifoldgen.runtime import set_threads


def main(scene: str, runs: int, time_limit: float) -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=runs)
    parser.add_argument("--time", type=float, default=time_limit)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default=f"bench-{scene}")
    parser.add_argument("--model", nargs="*", default=None, help="trained model directories (learned methods)")
    parser.add_argument("--methods", nargs="*", default=None)
    parser.add_argument("--resume", action="store_true")
    args = parser.parse_args()
    set_threads()  # as every command: torch's and numpy's BLAS threads sized for this machine
    methods = args.methods or default_methods(args.model)
    baseline = default_baseline(methods)
    table, summaries = run_bench(Experiment(scene, time_limit=args.time), methods, args.out, runs=args.runs,
                                 workers=args.workers, resume=args.resume, baseline=baseline)
    print(f"{scene}: {args.runs} runs per method, {args.time:g} s limit, {args.workers} workers -> {args.out}")
    print(table)
    reference = next((s for s in summaries if s.method == baseline), None)
    if reference is not None:
        for s in summaries:
            if s.method != baseline:
                print(f"{s.method}: median {s.time_median:.3g} s vs {reference.time_median:.3g} s "
                      f"({reference.time_median / s.time_median:.1f}x), success {s.success:.0f}% vs "
                      f"{reference.success:.0f}%")


if __name__ == "__main__":
    main("wall", 20, 30.0)
