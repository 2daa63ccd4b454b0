"""The compiled core's sphere broad phase on panda's wall and maze: cost per state and how often it flags.

    python benchmarks/bench_core_spheres.py [--states 2000] [--seed 0]

For ``--states`` uniform configurations projected onto the pose task's manifold, per scene: the share of
states in collision (coal), the share the sphere models flag (conservative: every collision is flagged),
the false positives (flagged, coal says free), misses (must be 0), and CPU microseconds per state of the
exact check (coal), of the sphere test alone, and of the broad phase followed by coal where it flags
(whose verdicts must equal coal's).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from manifoldgen import native
from manifoldgen.scene import get_scene
from manifoldgen.space import ConstrainedSpace
from manifoldgen.tasks import get_task


def per_state_us(check, q: np.ndarray) -> tuple[np.ndarray, float]:
    began = time.process_time()
    codes = check(q)
    return codes, (time.process_time() - began) / len(q) * 1e6


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--states", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    task = get_task("pose", "panda")
    print("| scene | spheres | in collision | flagged by spheres | false positives | missed | coal µs/state "
          "| spheres µs/state | spheres, then coal µs/state |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in ("wall", "maze"):
        scene = get_scene(task, name)
        space = ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))
        core = native.core_space(space)
        q = space.project(task.robot.sample_uniform(args.states, np.random.default_rng(args.seed))).q
        limit = np.full(len(q), np.inf)  # collision alone decides
        exact, coal_us = per_state_us(lambda x: core.codes(x, limit, True, True), q)
        spheres = native.space_spheres(space)
        native.set_spheres(core, spheres)
        flagged, sphere_us = per_state_us(lambda x: core.codes(x, limit, True, False), q)
        both, both_us = per_state_us(lambda x: core.codes(x, limit, True, True), q)
        if not np.array_equal(both, exact):
            raise SystemExit(f"{name}: the broad phase changed a verdict")
        hit, flag = exact == 4, flagged == 4
        print(f"| {name} | {len(spheres['radius'])} | {hit.mean():.1%} | {flag.mean():.1%} | {(flag & ~hit).mean():.1%} "
              f"| {int((hit & ~flag).sum())} | {coal_us:.1f} | {sphere_us:.1f} | {both_us:.1f} |")


if __name__ == "__main__":
    main()
