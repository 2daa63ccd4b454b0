"""Where a query's CPU goes: our planner's queries under ``perf``, sampled only inside ``Planner.solve``.

    python benchmarks/profile_query.py run --method cvae --model DIR [--seeds 0:30]   # timings, paths
    python benchmarks/profile_query.py perf --method cvae --model DIR -o cvae.data     # + perf record
    python benchmarks/profile_query.py split cvae.data                                 # shares by kind

The problem is OMPL's sphere demo by default (task ``sphere``, robot ``point``, scene ``sphere``, as
``bench_sphere_demo.py`` builds it), or any ``--task T --robot R --scene S`` (e.g. ``--task pose --robot panda
--scene maze --model src/manifoldgen/data/pretrained/panda-pose-cvae``), always with ``spheres=true`` and
any ``--set KEY=VALUE`` planner settings. ``run`` builds each seed's planner as the bench does and prints, per
seed, what identifies its search (solved, waypoints, their sum, iterations, samples, tree sizes: equal lines mean
equal decisions), then the median CPU of ``Planner.solve``. ``perf`` runs the same under ``perf record`` (Linux
perf; build the core with symbols for names inside it: ``pip install -e . -Ccmake.build-type=RelWithDebInfo``),
recording only while a query runs (perf's control FIFOs). ``split`` sums a recording's samples by kind of work.
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

KINDS = [  # (kind, shared object pattern, symbol pattern or None): the first match wins
    ("nearest neighbours + pool bookkeeping", "manifoldgen_core",
     r"Tree::|KdTree|Pool::|Search::far|rrt_connect|Cells|adjust_heap|hashtable|_Map_base|pair<double, int>"),
    ("space: residuals, Jacobians, projection, collision; local planner", r"manifoldgen_core|pinocchio|coal", None),
    ("CVAE decode (torch kernels)", r"torch_cpu|gomp", None),
    ("Python (interpreter, numpy, torch dispatch)", r"python|multiarray|torch_python", None),
    ("malloc/free, memcpy (libc)", r"libc\.so|libstdc\+\+", None),
    ("kernel", r"kernel", None),
]


def run(args: argparse.Namespace) -> None:
    from manifoldgen.bench.planning import Experiment, Method, build
    from manifoldgen.runtime import set_threads

    set_threads()
    first, stop = (int(v) for v in args.seeds.split(":"))
    from manifoldgen.planning import PLANNERS, planner_settings
    from manifoldgen.settings import parse_settings
    known = {k: v for name in PLANNERS.names() for k, v in planner_settings(name).items()}
    experiment = Experiment(args.scene, task=args.task, robot=args.robot, time_limit=10.0,
                            planner_settings={"spheres": True, **parse_settings(args.set, None, known, "planner")})
    method = Method.parse(f"cvae=rrtconnect@cvae:{args.model}" if args.method == "cvae" else "project=rrtconnect@project")
    control = (open(args.control, "w"), open(args.ack)) if args.control else None  # perf's FIFOs, open throughout

    def tell_perf(word: str) -> None:
        if control:
            control[0].write(word + "\n")
            control[0].flush()
            control[1].readline()  # perf's acknowledgement
    cpu = []
    for seed in range(first, stop):
        planner, scene, _ = build(experiment, method, seed)
        began = time.process_time()
        tell_perf("enable")
        result = planner.solve(scene.start, scene.goal, experiment.time_limit)
        tell_perf("disable")
        cpu.append(time.process_time() - began)
        print(seed, result.solved, len(result.path), f"{result.path.sum():.9f}", result.iterations,
              result.samples_drawn, result.extras.get("nodes"))
    print(f"{args.method}: median CPU {np.median(cpu):.4f} s, mean {np.mean(cpu):.4f} s over seeds {args.seeds}")


def record(args: argparse.Namespace) -> None:
    with tempfile.TemporaryDirectory() as folder:
        control, ack = Path(folder) / "control", Path(folder) / "ack"
        os.mkfifo(control), os.mkfifo(ack)
        holders = [os.open(control, os.O_RDWR), os.open(ack, os.O_RDWR)]  # keep both ends open for perf
        try:
            subprocess.run(["perf", "record", "-F", "4999", "-D", "-1", "--control", f"fifo:{control},{ack}",
                            "-o", args.output, sys.executable, __file__, "run", "--method", args.method,
                            "--model", str(args.model), "--seeds", args.seeds, "--task", args.task, "--robot",
                            args.robot, "--scene", args.scene, *(f"--set={v}" for v in args.set),
                            "--control", str(control),
                            "--ack", str(ack)], check=True)
        finally:
            for fd in holders:
                os.close(fd)


def split(args: argparse.Namespace) -> None:
    report = subprocess.run(["perf", "report", "-i", args.data, "--no-children", "--sort", "dso,sym", "-q",
                             "-g", "none"], capture_output=True, text=True, check=True).stdout
    shares: collections.Counter = collections.Counter()
    for line in report.splitlines():
        m = re.match(r"\s*([\d.]+)%\s+(\S+)\s+\[.\]\s+(.*)", line)
        if not m:
            continue
        share, dso, symbol = float(m.group(1)), m.group(2), m.group(3)
        kind = next((k for k, d, s in KINDS if re.search(d, dso) and (s is None or re.search(s, symbol))), "other")
        shares[kind] += share
    for kind, share in shares.most_common():
        print(f"{share:5.1f} %  {kind}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for name in ("run", "perf"):
        p = sub.add_parser(name)
        p.add_argument("--method", choices=("cvae", "project"), default="cvae")
        p.add_argument("--model", type=Path, default=Path("runs/sphere-demo-try/cvae"))
        p.add_argument("--seeds", default="0:30", help="FIRST:STOP")
        p.add_argument("--task", default="sphere")
        p.add_argument("--robot", default="point")
        p.add_argument("--scene", default="sphere")
        p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a planner setting")
        if name == "run":
            p.add_argument("--control", help=argparse.SUPPRESS)
            p.add_argument("--ack", help=argparse.SUPPRESS)
        else:
            p.add_argument("-o", "--output", default="perf.data")
    sub.add_parser("split").add_argument("data")
    args = parser.parse_args()
    {"run": run, "perf": record, "split": split}[args.command](args)


if __name__ == "__main__":
    main()
