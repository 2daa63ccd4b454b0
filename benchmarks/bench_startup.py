"""Start-up of the command line: ``manifoldgen --help`` and a whole ``manifoldgen plan`` process on the shipped
panda task with its shipped model (warm caches: one run first, not counted, which also writes the bytecode caches
that an install writes, even where the environment sets PYTHONDONTWRITEBYTECODE), wall and CPU of each process.

    python benchmarks/bench_startup.py [--runs 7]

Targets: ``--help`` at most 0.3 s, ``plan --no-picture`` at most 1.0 s wall (the median). Prints the machine's load
average beside them: this machine is shared.
"""

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import manifoldgen

MODEL = Path(manifoldgen.__file__).parent / "data" / "pretrained" / "panda-pose-cvae"
COMMAND = Path(sys.executable).with_name("manifoldgen")


ENVIRONMENT = {key: value for key, value in os.environ.items() if key != "PYTHONDONTWRITEBYTECODE"}


def timed(args: list[str]) -> tuple[float, float]:
    """Wall and CPU seconds (user + system) of one process running ``args``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=ENVIRONMENT)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        commands = {
            "manifoldgen --help": [str(COMMAND), "--help"],
            "manifoldgen plan (shipped model, --no-picture)": [
                str(COMMAND), "plan", "pose", "--robot", "panda", "--scene", "wall", "--sampler", f"model:{MODEL}",
                "--seed", "0", "--no-picture", "-o", os.path.join(folder, "p.npz")],
        }
        print(f"load average before: {os.getloadavg()[0]:.2f}")
        for name, command in commands.items():
            timed(command)  # warms the caches (collision matrix, sphere fit) and the file system
            runs = [timed(command) for _ in range(args.runs)]
            walls, cpus = zip(*runs)
            print(f"{name}: wall median {statistics.median(walls):.3f} s (min {min(walls):.3f}, max "
                  f"{max(walls):.3f}), CPU median {statistics.median(cpus):.3f} s over {args.runs} runs")
        print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
