"""The compiled core's sphere broad phase: cost per state, how often it flags, and that it changes no verdict.

    python benchmarks/bench_core_spheres.py [--states 2000] [--seed 0] [--scenes wall maze tray-over reach]

States on the task's manifold, per scene: panda's wall and maze and PR2's tray-over, uniform seeds projected at
the scene's condition; talos's reach (balance), seeds around the task's home (the stance neighbourhood, ``NEAR_HOME``
rad or m of spread) projected at the scene's condition, and as many midpoints of random pairs of them (what a
motion check visits). Printed: the share of states in collision (coal), the share the sphere models flag
(conservative: every collision is flagged), false positives (flagged, coal says free), misses (must be 0),
and CPU microseconds per state of the exact check without spheres (coal's broad phase over every pair), of
the sphere test alone, and of the exact check with spheres (spheres per pair, then for the pairs whose
spheres touch the convex hulls, then coal), whose verdicts must equal coal's (the script fails otherwise); then the same with the pairs left to coal
(spheres that nearly always touch) chosen on other task states besides uniform ones.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from manifoldgen import native
from manifoldgen.runtime import set_threads
from manifoldgen.scene import get_scene
from manifoldgen.space import ConstrainedSpace
from manifoldgen.spheres import SphereChecker
from manifoldgen.tasks import get_task

SCENES = {"wall": ("pose", "panda"), "maze": ("pose", "panda"), "tray-over": ("dualarm", "pr2"),
          "reach": ("balance", "talos")}
NEAR_HOME = 0.3


def per_state_us(check, q: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Results, CPU and wall microseconds per state."""
    cpu, wall = time.process_time(), time.perf_counter()
    codes = check(q)
    return codes, (time.process_time() - cpu) / len(q) * 1e6, (time.perf_counter() - wall) / len(q) * 1e6


def task_states(task, space: ConstrainedSpace, count: int, rng) -> np.ndarray:
    """(count', n) converged projections of seeds onto the scene's manifold (see the module docstring)."""
    robot = task.robot
    if task.name == "balance":
        seeds = np.clip(task.home + rng.normal(0, NEAR_HOME, (count // 2, robot.n)), robot.lower, robot.upper)
        q = space.project(seeds).q
        q = q[space.violation(q) <= 1]
        i, j = rng.integers(0, len(q), (2, count - len(q)))
        return np.concatenate([q, (q[i] + q[j]) / 2])
    return space.project(robot.sample_uniform(count, rng)).q


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--states", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scenes", nargs="*", default=list(SCENES), choices=list(SCENES))
    args = parser.parse_args()
    set_threads()  # as every command: torch's and numpy's BLAS threads sized for this machine
    print("| scene | states | spheres | in collision | flagged by spheres | false positives | missed "
          "| exact, no spheres µs/state | spheres alone µs/state | exact with spheres µs/state "
          "| pairs left to coal: uniform / + task states | flagged, task-chosen | exact with spheres, task-chosen µs/state |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.scenes:
        task = get_task(*SCENES[name])
        scene = get_scene(task, name)
        space = ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))
        core = native.core_space(space)
        q = task_states(task, space, args.states, np.random.default_rng(args.seed))
        limit = np.full(len(q), np.inf)  # collision alone decides
        exact, coal_cpu, coal_wall = per_state_us(lambda x: core.codes(x, limit, True, True), q)
        spheres = native.space_spheres(space)
        native.set_spheres(core, spheres)
        flagged, sphere_cpu, sphere_wall = per_state_us(lambda x: core.codes(x, limit, True, False), q)
        both, both_cpu, both_wall = per_state_us(lambda x: core.codes(x, limit, True, True), q)
        if not np.array_equal(both, exact):
            raise SystemExit(f"{name}: the broad phase changed {int(np.sum(both != exact))} verdicts")
        # the same with the pairs left to coal chosen on task states (the other half's seeds) besides uniform ones
        typical = task_states(task, space, args.states, np.random.default_rng(args.seed + 1))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the pairs left to coal are listed in "exact"
            tuned = SphereChecker(space.checker, typical=typical)
        native.set_spheres(core, {**spheres, "exact": list(tuned.exact_pairs)})
        flagged2 = core.codes(q, limit, True, False)
        both2, both2_cpu, both2_wall = per_state_us(lambda x: core.codes(x, limit, True, True), q)
        if not np.array_equal(both2, exact):
            raise SystemExit(f"{name}: the broad phase with task-chosen exact pairs changed a verdict")
        hit, flag = exact == 4, flagged == 4
        if np.any(hit & ~flag):
            raise SystemExit(f"{name}: {int(np.sum(hit & ~flag))} states in collision are free for the spheres")
        print(f"| {task.robot.name} {name} | {len(q)} | {len(spheres['radius'])} | {hit.mean():.1%} | {flag.mean():.1%} "
              f"| {(flag & ~hit).mean():.1%} | 0 | {coal_cpu:.1f} ({coal_wall:.1f}) "
              f"| {sphere_cpu:.1f} ({sphere_wall:.1f}) | {both_cpu:.1f} ({both_wall:.1f}) "
              f"| {len(spheres['exact'])} / {len(tuned.exact_pairs)} | {(flagged2 == 4).mean():.1%} "
              f"| {both2_cpu:.1f} ({both2_wall:.1f}) |", flush=True)


if __name__ == "__main__":
    main()
