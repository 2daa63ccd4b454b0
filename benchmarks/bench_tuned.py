"""The symmetric protocol: ours and C++ OMPL each tuned by the same procedure and budget, then compared.

    python benchmarks/bench_tuned.py [--problems wall maze talos] [--model talos=OUT/talos-cvae ...]
                                     [--methods cvae atlas-c++ tangent-c++ projected-c++] [--tune-seed 100]
                                     [--tune-runs 15] [--tune-time S] [--seed 0] [--runs 30] [--time 10]
                                     [--out runs/tuned] [--resume] [--one-set]

Every problem is planned by each method twice on the table's seeds (seed .. seed + runs - 1), interleaved per seed
in this one process: with its defaults (ours: the planner dataclass's, the task file's ``[planner]`` table left out;
OMPL's: :class:`~manifoldgen.ompl_settings.OmplSettings`, OMPL's own) and with the settings the tuning chose. Both
sides get the sphere broad phase, the same tolerance, the same dense check of every path and the same retry policy
(``manifoldgen.bench.planning.run_once``; paths that fail the dense check do not count).

Tuning, the same for every method: coordinate descent over the method's knobs (:data:`KNOBS`, three values each
with the default among them, two for a yes/no knob), on held-out seeds tune-seed .. tune-seed + tune-runs - 1: each
knob in turn, the others held at the best so far, every value planned on every held-out seed; the value with the
lowest median CPU (an unsolved run, or one past --tune-time, counts as slower than every solved one) is kept, a tie
keeping the earlier. A setting already planned is not planned again. Ours has five knobs, Atlas and TangentBundle
five (the atlas's), Projected two (it has no more). With --one-set each method gets one set for all the problems:
the same descent scored by the geometric mean of the problems' median CPU. ``--resume`` over the same --out reuses
every recorded run made with the same arguments.

Prints per problem the chosen settings, the tuning's distinct evaluations and CPU per method, and the table: solved,
median CPU (wall), path length and FK and collision-query counts of each method with its defaults and tuned, the
candidate paths the dense check refused (retry policies differ: OMPL starts a new tree keeping its charts, ours cuts
the refused edge and searches on), and each OMPL method's median CPU over ours in the same pairing. Records:
OUT/PROBLEM/tuning.jsonl and runs.jsonl, the table's (every run, its path included: ``python examples/check_path.py
OUT/PROBLEM`` rechecks them outside the project with OUT/PROBLEM/problem.json).
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import fields
from pathlib import Path

import numpy as np

from manifoldgen.bench.planning import PROBLEM_FILE, RUNS_FILE, Experiment, Method, problem_meta, run_once
from manifoldgen.io import atomic_write_text
from manifoldgen.models import pretrained_model_dir
from manifoldgen.planning.rrt_connect import RRTConnectSettings
from manifoldgen.runtime import set_threads

# problem -> (task, robot, scene, our sampler spec with {model}, time limit s)
PROBLEMS = {
    "wall": ("pose", "panda", "wall", "cvae:{model}", 10.0),
    "maze": ("pose", "panda", "maze", "cvae:{model}", 10.0),
    "talos": ("balance", "talos", "reach", "cvae:{model}", 30.0),
    "dualarm": ("dualarm", "pr2", "tray-over", "cvae:{model}", 30.0),
    "drinkcan": ("drinkcan", "centauro", "drinkcan", "cvae:{model}", 30.0),
}
METHODS = {"cvae": "rrtconnect@{sampler}", "atlas-c++": "ompl-native-atlas", "tangent-c++": "ompl-native-tangent",
           "projected-c++": "ompl-native-projected"}
ATLAS = {"ompl_range": [0.6, 0.45, 0.9], "ompl_epsilon": [0.05, 0.1, 0.2], "ompl_rho": [0.0, 0.15, 0.4],
         "ompl_exploration": [0.75, 0.5, 0.9], "ompl_separated": [True, False]}
KNOBS = {  # method -> knob -> values, the default first (ompl_rho 0: OMPL's 5 x delta = 0.25 rad)
    "cvae": {"range": [0.6, 0.45, 0.9], "reach": [0.5, 0.35, 0.7], "edges": ["coarse:2", "coarse:1", "dense:4"],
             "pool": [2048, 0, 512], "candidates": [8, 4, 16]},
    "atlas-c++": ATLAS, "tangent-c++": ATLAS,
    "projected-c++": {"ompl_range": [0.6, 0.45, 0.9], "ompl_lambda": [2.0, 1.5, 4.0]},
}
OURS_DEFAULTS = {f.name: f.default for f in fields(RRTConnectSettings)}


def median_cpu(records: list[dict], limit: float = np.inf) -> float:
    """Median CPU with an unsolved run (or one over ``limit`` s) slower than every solved one (inf when most are)."""
    return float(np.median([r["cpu_s"] if r["solved"] and r["time_s"] <= limit else np.inf for r in records]))


class Problem:
    """One problem's runs: every (method, settings, seed) planned at most once, its record kept in a JSON-lines file."""

    def __init__(self, name: str, model: str, time_limit: float | None, out: Path, resume: bool):
        task, robot, scene, sampler, limit = PROBLEMS[name]
        self.name, self.sampler = name, sampler.format(model=model)
        self.base = Experiment(scene, task, robot, limit if time_limit is None else time_limit)
        self.out = out / name
        self.out.mkdir(parents=True, exist_ok=True)
        self.done: dict[str, dict] = {}
        self.resume = resume

    def plan(self, file: str, method: str, settings: dict, seed: int, time_limit: float = np.inf) -> dict:
        """The record of ``method`` with ``settings`` (over its defaults) at ``seed`` within the problem's time limit
        or ``time_limit`` s if shorter, planned unless recorded (a record made with a longer limit is kept)."""
        key = json.dumps([method, settings, seed], sort_keys=True)
        if key not in self.done:
            spec = f"{method}={METHODS[method].format(sampler=self.sampler)}"
            ours = {} if method.endswith("-c++") else OURS_DEFAULTS
            experiment = Experiment(self.base.scene, self.base.task, self.base.robot,
                                    min(self.base.time_limit, time_limit), seed,
                                    planner_settings={**ours, "spheres": True, **settings})
            record = run_once(experiment, Method.parse(spec), 0)
            record.update(key=key, settings=settings)
            if file == "tuning.jsonl":
                record.pop("path", None)
            with open(self.out / file, "a") as stream:
                stream.write(json.dumps(record) + "\n")
            self.done[key] = record
        return self.done[key]

    def load(self, arguments: dict) -> None:
        """Earlier records (``--resume``), refused when they were made with other arguments; else a fresh start."""
        config = self.out / "config.json"
        if self.resume and config.is_file():
            if json.loads(config.read_text()) != arguments:
                raise SystemExit(f"{config}: made with other arguments; resume with the same ones or use another --out")
            for file in ("tuning.jsonl", RUNS_FILE):
                path = self.out / file
                for line in path.read_text().splitlines() if path.is_file() else []:
                    if line.strip():
                        record = json.loads(line)
                        self.done[record["key"]] = record
        else:
            for file in ("tuning.jsonl", RUNS_FILE):
                (self.out / file).unlink(missing_ok=True)
        atomic_write_text(config, json.dumps(arguments, indent=1))
        atomic_write_text(self.out / PROBLEM_FILE, json.dumps(problem_meta(self.base), indent=1))


def tune(problems: list[Problem], method: str, seeds: range, limit: float) -> tuple[dict, int, float]:
    """Coordinate descent over the method's knobs on ``seeds`` of every problem, each query within ``limit`` s,
    scored by the geometric mean of the problems' median CPU: (chosen settings, distinct settings planned, CPU s
    of the tuning's queries)."""
    best: dict = {}
    evaluated: dict[str, float] = {}

    def score(settings: dict) -> float:
        settings = {k: v for k, v in settings.items() if v != KNOBS[method][k][0]}  # one name per setting
        key = json.dumps(settings, sort_keys=True)
        if key not in evaluated:
            medians = [median_cpu([p.plan("tuning.jsonl", method, settings, s, limit) for s in seeds], limit)
                       for p in problems]
            evaluated[key] = float(np.exp(np.mean(np.log(medians))))
        return evaluated[key]

    for knob, values in KNOBS[method].items():
        scores = [score({**best, knob: value}) for value in values]
        best = {**best, knob: values[int(np.argmin(scores))]}
    cpu = sum(r.get("cpu_s", 0.0) for p in problems for r in p.done.values()
              if r["method"] == method and r["seed"] in seeds)
    return {k: v for k, v in best.items() if v != KNOBS[method][k][0]}, len(evaluated), cpu


def row(label: str, records: list[dict], ours: list[dict] | None) -> str:
    solved = [r for r in records if r["solved"]]
    med = (lambda key: np.median([r[key] for r in solved])) if solved else (lambda key: np.nan)
    ops = (lambda key: f"{np.median([r['ops'][key] for r in solved]):,.0f}") if solved else (lambda key: "-")
    queries = [r["extras"].get("sphere_checks", 0) + r["extras"].get("sweep_checks", 0) for r in solved]
    ratio = f"{median_cpu(records) / median_cpu(ours):.2f}x" if ours is not None else "-"
    rejected = sum(r.get("extras", {}).get("rejected_paths", 0) for r in records)
    return (f"| {label} | {len(solved)}/{len(records)} | {med('cpu_s'):.4g} ({med('time_s'):.4g}) | "
            f"{med('length'):.2f} | {ops('fk')} | {f'{np.median(queries):,.0f}' if solved else '-'} | {rejected} | "
            f"{ratio} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problems", nargs="+", default=["wall", "maze"], choices=sorted(PROBLEMS))
    parser.add_argument("--model", action="append", default=[], metavar="PROBLEM=DIR",
                        help="our CVAE for a problem (wall and maze: the shipped panda model by default)")
    parser.add_argument("--methods", nargs="+", default=["cvae", "atlas-c++"], choices=sorted(METHODS))
    parser.add_argument("--tune-seed", type=int, default=100)
    parser.add_argument("--tune-runs", type=int, default=15)
    parser.add_argument("--tune-time", type=float, default=None, help="time limit of a tuning query, s (default: "
                        "the problem's); a setting whose median query takes longer loses")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--runs", type=int, default=30)
    parser.add_argument("--time", type=float, default=None, help="time limit per query, s (default: the problem's)")
    parser.add_argument("--out", default="runs/tuned")
    parser.add_argument("--resume", action="store_true")
    parser.add_argument("--one-set", action="store_true", help="tune one set of settings per method for all the "
                        "problems together (the geometric mean of their median CPU) instead of one per problem")
    args = parser.parse_args()
    models = dict(m.split("=", 1) for m in args.model)
    for name in args.problems:
        if name not in models and name not in ("wall", "maze"):
            parser.error(f"problem {name} needs its model: --model {name}=DIR (a CVAE trained on its task)")
    tune_seeds = range(args.tune_seed, args.tune_seed + args.tune_runs)
    seeds = range(args.seed, args.seed + args.runs)
    if set(tune_seeds) & set(seeds):
        parser.error(f"the held-out seeds {tune_seeds.start}..{tune_seeds.stop - 1} overlap the table's "
                     f"{seeds.start}..{seeds.stop - 1}; move --tune-seed")
    set_threads()  # one torch thread, as the bench's workers
    out = Path(args.out)
    problems = [Problem(name, models.get(name, str(pretrained_model_dir())), args.time, out, args.resume)
                for name in args.problems]
    for problem in problems:
        kept = {k: v for k, v in vars(args).items() if k not in ("problems", "resume", "out", "one_set", "tune_time")}
        problem.load(kept | {"model": models.get(problem.name, "shipped")})
    groups = [problems] if args.one_set else [[p] for p in problems]
    for group in groups:
        print(f"## {', '.join(p.name for p in group)}: tuning on seeds {tune_seeds.start}..{tune_seeds.stop - 1}"
              + (" (one set of settings for all, by the geometric mean of their median CPU)" if args.one_set else ""),
              flush=True)
        tuned = {}
        for method in args.methods:
            tuned[method], count, cpu = tune(group, method, tune_seeds, args.tune_time or np.inf)
            print(f"- {method}: {json.dumps(tuned[method]) if tuned[method] else 'its defaults'} "
                  f"({count} settings tried, {cpu:.1f} s CPU in queries)", flush=True)
        for problem in group:
            began = time.process_time()
            table = {(m, pairing): [] for m in args.methods for pairing in ("defaults", "tuned")}
            for seed in seeds:  # interleaved per seed
                for method in args.methods:
                    for pairing, settings in (("defaults", {}), ("tuned", tuned[method])):
                        table[method, pairing].append(problem.plan(RUNS_FILE, method, settings, seed))
            lines = [f"### {problem.name}: seeds {seeds.start}..{seeds.stop - 1}, {problem.base.time_limit:g} s "
                     f"limit ({time.process_time() - began:.0f} s CPU here)",
                     "| method | solved | median CPU (wall), s | path length, rad | FK | collision queries | "
                     "paths the dense check refused (all runs) | CPU over ours |", "|---|---|---|---|---|---|---|---|"]
            for pairing in ("defaults", "tuned"):
                ours = table["cvae", pairing] if "cvae" in args.methods else None
                for method in args.methods:
                    lines.append(row(f"{method}, {pairing}", table[method, pairing],
                                     None if method == "cvae" else ours))
            atomic_write_text(problem.out / "results.md", "\n".join(lines) + "\n")
            print("\n".join(lines), flush=True)


if __name__ == "__main__":
    main()
