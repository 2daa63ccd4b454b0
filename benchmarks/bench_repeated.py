"""Repeated queries on one manifold and scene: 100 random start/goal pairs in the panda maze, one process.

    python benchmarks/bench_repeated.py [--queries 100] [--seed 0] [--time 10] [--methods cold reuse prm atlas-c++]
                                        [--pairs PAIRS.npy] [--grouped] [--prm-samples 2000]

Methods, interleaved per query (``--grouped``: each method's queries back to back, caches warm): ``cold``, the
shipped CVAE with RRT-Connect (its search in the compiled core), one planner whose queries start from nothing;
``reuse``, the same with ``reuse=true`` (the paths found so far are a roadmap that later queries search first,
:mod:`manifoldgen.planning.roadmap`); ``prm``, the same planner whose roadmap is first built from the same CVAE's
samples (a PRM on the same samples, ``Planner.roadmap_of``: --prm-samples valid states, each joined to its 10
nearest within the planner's range by segments that pass the dense check; its making is timed apart, not in any
query); ``atlas-c++``, C++ OMPL Atlas + RRTConnect, cold (each query its own program). All with sphere models as the
collision broad phase. Start and goal are valid, collision-free states of the maze's manifold in the component of
the scene's start (the CVAE's samples, drawn with another seed than the planners', that RRT-Connect with the CVAE
reaches from there within 1 s). Every path is rechecked here by the Python space's dense check (not the planners'
own) and its ends compared; numpy's BLAS runs on one thread, as in every command (its idle threads would spin after
the recheck, into the next solve's CPU, which counts all of this process's threads). CPU: ours, this process's over
``solve``; Atlas's, its program's from "go" plus our dense check of its paths (as ``bench_ompl_native.py`` counts
it), its wall from "go" (not the program's start and loading). Prints, per method: solved and rechecked, median CPU
and wall over all queries and over queries 2.., routed queries (reuse, prm: answered from the roadmap) and their
median CPU, median path length, the CPU of all queries.
"""

import argparse
import time
from pathlib import Path

import numpy as np

from manifoldgen.models import pretrained_model_dir
from manifoldgen.planning import RRTConnect, RRTConnectSettings
from manifoldgen.runtime import set_threads
from manifoldgen.scene import get_scene
from manifoldgen.space import ConstrainedSpace
from manifoldgen.specs import make_sampler
from manifoldgen.tasks import get_task

METHODS = ("cold", "reuse", "prm", "atlas-c++")


def queries(space: ConstrainedSpace, start: np.ndarray, count: int, seed: int, time_limit: float = 1.0) -> np.ndarray:
    """(count, 2, n) start/goal pairs in the component of the manifold's free part that holds ``start`` (the scene's):
    the shipped CVAE's samples (the region the model covers, drawn with another seed than the planners') that pass
    the space's whole check and that RRT-Connect with the CVAE reaches from ``start`` within ``time_limit`` s (a choice
    of queries, not timed)."""
    sampler = make_sampler(f"cvae:{pretrained_model_dir()}", space, seed + 1_000_000)
    probe = RRTConnect(space, make_sampler(f"cvae:{pretrained_model_dir()}", space, seed + 2_000_000),
                       seed=seed, settings=RRTConnectSettings(spheres=True))
    states: list[np.ndarray] = []
    while len(states) < 2 * count:
        rows = sampler.sample_many(64)
        for q in rows[space.valid(rows)]:
            if len(states) < 2 * count and probe.solve(start, q, time_limit).solved:
                states.append(q)
    return np.array(states).reshape(count, 2, space.n)


def planner_for(method: str, space: ConstrainedSpace, seed: int):
    if method == "atlas-c++":
        from manifoldgen.ompl_native import NativeOmplPlanner
        return NativeOmplPlanner(space, ompl_space="atlas", seed=seed, spheres=True)
    sampler = make_sampler(f"cvae:{pretrained_model_dir()}", space, seed)
    return RRTConnect(space, sampler, seed=seed, settings=RRTConnectSettings(spheres=True, reuse=method != "cold"))


def sample_roadmap(planner: RRTConnect, space: ConstrainedSpace, count: int, seed: int) -> None:
    """Give ``planner`` a roadmap made from ``count`` of the CVAE's samples that pass the space's whole check (drawn
    with another seed than the planners'): a PRM on the same samples; prints what making it cost."""
    cpu, wall = time.process_time(), time.perf_counter()
    sampler, states = make_sampler(f"cvae:{pretrained_model_dir()}", space, seed + 3_000_000), []
    while sum(map(len, states)) < count:
        rows = sampler.sample_many(256)
        states.append(rows[space.valid(rows)])
    planner.roadmap_of(np.concatenate(states)[:count])
    roadmap = planner.roadmap
    print(f"prm: a roadmap of {len(roadmap)} samples and {roadmap.edge_count()} edges ({roadmap.checks} segments "
          f"checked) made in {time.process_time() - cpu:.1f} s CPU, {time.perf_counter() - wall:.1f} s wall")


def recheck(space: ConstrainedSpace, record: list, result, start: np.ndarray, goal: np.ndarray) -> None:
    """Fill ``record``'s checked field: the path ends at ``start`` and ``goal`` and passes the space's dense check."""
    record[1] = bool(result.solved and np.allclose(result.path[[0, -1]], [start, goal])
                     and space.validate_path(result.path).valid)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--queries", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--time", type=float, default=10.0)
    parser.add_argument("--methods", nargs="*", default=list(METHODS), choices=METHODS)
    parser.add_argument("--grouped", action="store_true", help="each method's queries back to back, their paths "
                        "rechecked after all of them (warm caches); default: methods interleaved per query, each path "
                        "rechecked at once")
    parser.add_argument("--prm-samples", type=int, default=2000, help="valid samples of the prm method's roadmap")
    parser.add_argument("--pairs", default=None, help="an .npy file of the start/goal pairs: read when it exists "
                        "(its queries, not --queries), else written after they are chosen (choosing takes minutes)")
    args = parser.parse_args()
    set_threads()  # as every command: numpy's BLAS on one thread (the recheck's BLAS threads would spin into solves)
    task = get_task("pose")
    scene = get_scene(task, "maze")
    space = ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))
    if args.pairs and Path(args.pairs).exists():
        pairs = np.load(args.pairs)
    else:
        pairs = queries(space, scene.start, args.queries, args.seed)
        if args.pairs:
            np.save(args.pairs, pairs)
    planners = {m: planner_for(m, space, args.seed) for m in args.methods}
    if "prm" in planners:
        sample_roadmap(planners["prm"], space, args.prm_samples, args.seed)
    runs = {m: [] for m in args.methods}
    order = ([(k, m) for m in args.methods for k in range(len(pairs))] if args.grouped
             else [(k, m) for k in range(len(pairs)) for m in args.methods])
    unchecked = []  # grouped: the paths are rechecked after every query has run
    for k, method in order:
        start, goal = pairs[k]
        planner = planners[method]
        if method == "atlas-c++":
            planner.seed = args.seed + k
        cpu, wall = time.process_time(), time.perf_counter()
        result = planner.solve(start, goal, args.time)
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        if method == "atlas-c++":  # its program's CPU from "go" and our dense check of its paths, as the bench's
            cpu, wall = result.extras["native_cpu_s"] + result.extras["dense_cpu_s"], result.time_s
        routed = bool(result.extras.get("roadmap", {}).get("routed", False))
        runs[method].append([result.solved, None, cpu, wall, routed, result.length])
        if args.grouped:
            unchecked.append((runs[method][-1], result, start, goal))
        else:
            recheck(space, runs[method][-1], result, start, goal)
        print(f"query {k + 1}/{len(pairs)} {method}", end="\r", flush=True)
    for item in unchecked:
        recheck(space, *item)
    print(f"{len(pairs)} queries (seed {args.seed}), panda maze, {args.time:g} s limit, "
          + ("each method's queries back to back" if args.grouped else "methods interleaved"))
    print("| method | solved | rechecked | median CPU (s) | median wall (s) | median CPU, queries 2.. (s) "
          "| median wall, queries 2.. (s) | routed | median CPU, routed (s) | path length (rad, median) "
          "| CPU, all queries (s) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for method, rows in runs.items():
        solved, checked, cpu, wall, routed, length = (np.array(c) for c in zip(*rows))
        print(f"| {method} | {solved.sum()}/{len(rows)} | {checked.sum()}/{len(rows)} | {np.median(cpu):.4f} | "
              f"{np.median(wall):.4f} | {np.median(cpu[1:]):.4f} | {np.median(wall[1:]):.4f} | {routed.sum()} | "
              f"{f'{np.median(cpu[routed]):.4f}' if routed.any() else '-'} | {np.median(length[solved]):.2f} | "
              f"{cpu.sum():.3f} |")


if __name__ == "__main__":
    main()
