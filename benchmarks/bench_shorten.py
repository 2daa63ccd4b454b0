"""Our shortening applied to the paths another method found: is a length gap the search's route or the shortening?

    python benchmarks/bench_shorten.py RUNS_DIR [--method atlas-c++] [--attempts 50]

RUNS_DIR is a ``manifoldgen bench plan`` output folder (its ``config.json`` holds the experiment; its
``runs.jsonl`` every solved path). Each solved path of ``--method`` gets our shortening as ``--smooth`` runs it
(:func:`manifoldgen.planning.smoothing.shortcut`, ``--attempts`` attempts, then
:func:`~manifoldgen.planning.smoothing.relax`, the Python twins of the core's), in the space the benchmark judged
that method's paths in (:func:`manifoldgen.bench.planning.method_space`), with the auto local planner. Prints
per seed the path's length as recorded and after our shortening, whether the shortened path passes the dense
check, and the medians.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from manifoldgen.bench.planning import CONFIG_FILE, RUNS_FILE, Experiment, Method, method_space, read_records
from manifoldgen.native import fast_space
from manifoldgen.planning import relax, shortcut
from manifoldgen.planning.local import make_local
from manifoldgen.planning.result import path_length
from manifoldgen.runtime import set_threads


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, help="a bench plan output folder")
    parser.add_argument("--method", default="atlas-c++", help="the label of the method whose paths are shortened")
    parser.add_argument("--attempts", type=int, default=50, help="shortcut attempts (the bench's --set shortcut)")
    args = parser.parse_args()
    set_threads()
    experiment = Experiment(**json.loads((args.runs / CONFIG_FILE).read_text())["experiment"])
    rows = [r for r in read_records(args.runs / RUNS_FILE) if r["method"] == args.method and r["solved"]]
    if not rows:
        raise SystemExit(f"{args.runs}/{RUNS_FILE} holds no solved run of method '{args.method}'")
    space = fast_space(method_space(experiment, Method.parse(rows[0]["spec"]).sampler))
    local = make_local("auto", space)
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
