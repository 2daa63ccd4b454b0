"""Our shortening applied to the paths another method found: is a length gap the search's route or the shortening?

    python benchmarks/bench_shorten.py RUNS_DIR [--method atlas-c++] [--attempts 50]

RUNS_DIR is a ``manifoldgen bench plan`` output folder (its ``config.json`` names the task, robot and scene; its
``runs.jsonl`` holds every solved path). Each solved path of ``--method`` gets our shortening as ``--smooth`` runs it
(:func:`manifoldgen.planning.smoothing.shortcut`, ``--attempts`` attempts, then
:func:`~manifoldgen.planning.smoothing.relax`, the Python twins of the core's), in the scene's constrained space
with the auto local planner. Prints per seed the path's length as recorded and after our shortening, whether the
shortened path passes the dense check, and the medians.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import manifoldgen as mg
from manifoldgen.bench.planning import read_records
from manifoldgen.native import fast_space
from manifoldgen.planning import relax, shortcut
from manifoldgen.planning.local import make_local
from manifoldgen.planning.result import path_length
from manifoldgen.runtime import set_threads
from manifoldgen.space import ConstrainedSpace


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, help="a bench plan output folder")
    parser.add_argument("--method", default="atlas-c++", help="the label of the method whose paths are shortened")
    parser.add_argument("--attempts", type=int, default=50, help="shortcut attempts (the bench's --set shortcut)")
    args = parser.parse_args()
    set_threads()
    experiment = json.loads((args.runs / "config.json").read_text())["experiment"]
    task = mg.load_task(experiment["task"], robot=experiment["robot"])
    scene = mg.load_scene(task, experiment["scene"])
    space = fast_space(ConstrainedSpace(task.constraint, task.condition.check(scene.condition)[0],
                                        scene.checker(task.robot)))
    local = make_local("auto", space)
    rows = [r for r in read_records(args.runs / "runs.jsonl") if r["method"] == args.method and r["solved"]]
    if not rows:
        raise SystemExit(f"{args.runs}/runs.jsonl holds no solved run of method '{args.method}'")
    before, after = [], []
    for record in rows:
        path = np.asarray(record["path"], float)
        shorter, _ = shortcut(path, local, attempts=args.attempts, time_limit=60.0)
        taut, _ = relax(shorter, local, time_limit=60.0)
        before.append(path_length(path))
        after.append(path_length(taut))
        print(f"seed {record['seed']}: {before[-1]:.2f} rad as recorded, {after[-1]:.2f} after our shortening "
              f"({'VALID' if space.validate_path(taut).valid else 'INVALID'})", flush=True)
    print(f"{args.method}, {len(rows)} paths: median {np.median(before):.2f} rad as recorded, {np.median(after):.2f} "
          "after our shortening")


if __name__ == "__main__":
    main()
