"""Planning speed on the panda pose scenes: success rate and time per sampler (one process).

    python benchmarks/bench_planning_quick.py [--runs 20] [--time 30] [--scenes wall maze]
        [--sampler pg:pose.npz --sampler cvae:runs/cvae ...] [--planner rrtconnect] [--local auto]
        [--set range=0.6 --set pool=1024 ...]

Default samplers: ``project`` and ``pg`` (10 000 rows collected at the scene's height, seed 0),
plus the shipped model when the package has one. Every run uses seed r = 0..runs-1, a fresh
sampler and planner; times are wall-clock ``PlanResult.time_s`` (sampling, search and the
final dense validation included), and the process CPU time of ``solve`` (the figure to
trust on a loaded machine). Every returned path is re-validated here.
Targets (panda pose, learned sampler): wall 100 % with mean <= 0.1 s; maze 100 %, mean <= 2 s.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # tiny matrices: BLAS threads only add overhead

import argparse  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from manifoldgen.data import collect  # noqa: E402
from manifoldgen.planning import DEFAULT_LOCAL, PLANNERS  # noqa: E402
from manifoldgen.runtime import set_threads
from manifoldgen.scene import get_scene  # noqa: E402
from manifoldgen.space import ConstrainedSpace  # noqa: E402
from manifoldgen.specs import make_sampler  # noqa: E402
from manifoldgen.tasks import get_task  # noqa: E402


def default_samplers(task, scene, folder: Path) -> list[str]:
    data = collect(task, 10_000, seed=0, conditions=[scene.condition], progress=False)
    data.save(folder / "pg.npz")
    specs = ["project", f"pg:{folder / 'pg.npz'}"]
    try:
        from manifoldgen.models import pretrained_model_dir
        specs.append(f"cvae:{pretrained_model_dir()}")
    except (ImportError, ValueError):
        pass  # no shipped model (yet)
    return specs


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--time", type=float, default=30.0)
    parser.add_argument("--scenes", nargs="*", default=["wall", "maze"])
    parser.add_argument("--sampler", action="append", default=None, help="sampler spec (repeatable)")
    parser.add_argument("--planner", default="rrtconnect")
    parser.add_argument("--local", default=DEFAULT_LOCAL)
    parser.add_argument("--set", action="append", default=[], help="planner setting key=value (repeatable)")
    args = parser.parse_args()
    set_threads()  # as every command: torch's and numpy's BLAS threads sized for this machine
    torch.set_num_threads(1)
    task = get_task("pose", "panda")
    cls = PLANNERS.get(args.planner)
    defaults = cls.settings_type()
    overrides = {k: type(getattr(defaults, k))(v == "True" if isinstance(getattr(defaults, k), bool) else v)
                 for k, v in (item.split("=") for item in args.set)}
    print("| scene | sampler | planner | success | mean s | median s | max s | mean CPU s | samples | length rad |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.scenes:
            scene = get_scene(task, name)
            space = ConstrainedSpace(task.constraint, scene.condition, scene.checker(task.robot))
            for spec in args.sampler or default_samplers(task, scene, Path(tmp)):
                times, cpu, lengths, samples, solved = [], [], [], [], 0
                for seed in range(args.runs):
                    planner = cls(space, make_sampler(spec, space, seed), local=args.local, seed=seed,
                                  settings=cls.settings_type(**overrides))
                    began = time.process_time()
                    result = planner.solve(scene.start, scene.goal, args.time)
                    cpu.append(time.process_time() - began)
                    times.append(result.time_s)
                    samples.append(result.samples_drawn)
                    if result.solved:
                        report = space.validate_path(result.path)
                        assert report.valid, report.reason
                        solved += 1
                        lengths.append(result.length)
                label = spec if len(spec) < 40 else f"{spec[:12]}...{spec[-24:]}"
                print(f"| {name} | {label} | {args.planner}/{args.local} | {solved / args.runs:.0%} | "
                      f"{np.mean(times):.3f} | {np.median(times):.3f} | {np.max(times):.3f} | {np.mean(cpu):.3f} | "
                      f"{np.mean(samples):.0f} | {np.mean(lengths) if lengths else float('nan'):.2f} |", flush=True)


if __name__ == "__main__":
    main()
