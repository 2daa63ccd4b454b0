"""The compiled core's dense path check with certified sweeps against state by state, on planned paths.

    python benchmarks/bench_sweeps.py [--seeds 10] [--scenes wall maze talos dualarm drinkcan] [--repeats 5]
                                      [--talos-model /tmp/bal3/talos-cvae] [--drinkcan-model /tmp/bal3/drinkcan-cvae]

Plans one path per seed with the compiled core and sphere models (panda wall and maze: the shipped CVAE;
talos reach: the CVAE at --talos-model, the balance bench's settings; PR2 dual-arm tray-over: the projection
sampler; centauro drinkcan: the CVAE at --drinkcan-model; the last two with their task's planner settings), then
checks every path with
``validate_path`` state by state and with certified sweeps (``set_sweeps``), asserting equal reports. Prints per
scene the medians per path: dense states, per-state checks (each: spheres, then hulls and coal where they
touch), sweep tests, collision queries (the two together), hull tests, coal mesh tests and CPU time per check.
"""

import argparse
import time
from dataclasses import fields

import numpy as np

from manifoldgen.models import pretrained_model_dir
from manifoldgen.planning import RRTConnect, RRTConnectSettings
from manifoldgen.runtime import set_threads
from manifoldgen.scene import get_scene
from manifoldgen.space import ConstrainedSpace
from manifoldgen.specs import make_sampler
from manifoldgen.tasks import get_task

COUNTS = ("sphere_checks", "sweep_checks", "hull_tests", "mesh_tests")


def planned(scene_name: str, seeds: int, talos_model: str, drinkcan_model: str):
    """(core with sphere models, [paths (K, n)]) of ``seeds`` solved queries."""
    if scene_name == "talos":
        task, spec = get_task("balance", "talos"), f"cvae:{talos_model},batch=256"
        scene = get_scene(task, "reach")
        settings = dict(pool=32, pool_batch=64, resolution=0.02)
    elif scene_name in ("dualarm", "drinkcan"):
        task = get_task("dualarm", "pr2") if scene_name == "dualarm" else get_task("drinkcan", "centauro")
        spec = "project" if scene_name == "dualarm" else f"cvae:{drinkcan_model},batch=256"
        scene = get_scene(task, "tray-over" if scene_name == "dualarm" else "drinkcan")
        known = {f.name for f in fields(RRTConnectSettings)} - {"core", "spheres"}
        settings = {k: v for k, v in task.planner.items() if k in known}
    else:
        task, spec = get_task("pose", "panda"), f"cvae:{pretrained_model_dir()}"
        scene = get_scene(task, scene_name)
        settings = {}
    paths, core = [], None
    for seed in range(seeds):
        space = ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))
        planner = RRTConnect(space, make_sampler(spec, space, seed), seed=seed,
                             settings=RRTConnectSettings(core="native", spheres=True, **settings))
        result = planner.solve(scene.start, scene.goal, 30.0)
        if result.solved:
            paths.append(np.ascontiguousarray(result.path))
        core = planner.core
    return core, paths


def measure(core, path: np.ndarray, sweeps: bool, repeats: int):
    """(report, {count: per check}, CPU s per check) of ``repeats`` dense checks of ``path``."""
    core.set_sweeps(sweeps)
    before, cpu = core.counts(), time.process_time()
    for _ in range(repeats):
        report = core.validate_path(path)
    cpu = (time.process_time() - cpu) / repeats
    after = core.counts()
    return report, {k: (after[k] - before[k]) / repeats for k in COUNTS}, cpu


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--scenes", nargs="*", default=["wall", "maze", "talos", "dualarm", "drinkcan"])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--talos-model", default="/tmp/bal3/talos-cvae")
    parser.add_argument("--drinkcan-model", default="/tmp/bal3/drinkcan-cvae")
    args = parser.parse_args()
    set_threads()  # as every command: torch's and numpy's BLAS threads sized for this machine
    print("| scene | dense check | paths | dense states | per-state checks | sweep tests | collision queries "
          "| hull tests | coal mesh tests | CPU per check (ms) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for scene in args.scenes:
        core, paths = planned(scene, args.seeds, args.talos_model, args.drinkcan_model)
        rows = {False: [], True: []}
        for path in paths:
            reports = {}
            for sweeps in (False, True):
                reports[sweeps], counts, cpu = measure(core, path, sweeps, args.repeats)
                rows[sweeps].append([reports[sweeps][5], counts["sphere_checks"], counts["sweep_checks"],
                                     counts["sphere_checks"] + counts["sweep_checks"], counts["hull_tests"],
                                     counts["mesh_tests"], cpu * 1e3])
            assert reports[True] == reports[False], (scene, reports)
        for sweeps in (False, True):
            m = np.median(np.array(rows[sweeps]), axis=0)
            print(f"| {scene} | {'certified sweeps' if sweeps else 'state by state'} | {len(paths)} | {m[0]:,.0f} | "
                  f"{m[1]:,.0f} | {m[2]:,.0f} | {m[3]:,.0f} | {m[4]:,.0f} | {m[5]:,.0f} | {m[6]:.2f} |")
        core.set_sweeps(True)


if __name__ == "__main__":
    main()
