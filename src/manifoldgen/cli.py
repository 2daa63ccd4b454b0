"""The ``manifoldgen`` command line: a thin typer layer over the library."""

from __future__ import annotations

import functools
import warnings
from pathlib import Path

import typer
from rich.console import Console

from manifoldgen.errors import ManifoldgenError

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Constrained motion planning with learned samplers.")
bench_app = typer.Typer(no_args_is_help=True, help="Experiments behind the paper's tables.")
app.add_typer(bench_app, name="bench")
console = Console(soft_wrap=True)


def friendly(command):
    """Turn ManifoldgenError into a one-line error and exit code 2; warnings print in yellow."""
    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        def show(message, category, filename, lineno, file=None, line=None):
            console.print(f"[yellow]warning:[/] {message}")
        warnings.showwarning = show
        try:
            return command(*args, **kwargs)
        except ManifoldgenError as exc:
            console.print(f"[red]error:[/] {exc}")
            raise typer.Exit(2) from None
    return wrapper


def _task(task: str, robot: str):
    from manifoldgen.tasks import get_task
    return get_task(task, robot)


def _check_conditions(task_obj, condition: list[float] | None, strict: bool):
    if condition is None:
        return None
    return task_obj.condition.check([[v] for v in condition] if task_obj.condition.k == 1 else [condition],
                                    strict=strict)


@app.command()
@friendly
def collect(task: str = typer.Argument(..., help="Task name, e.g. pose"),
            robot: str = typer.Option("panda", help="example-robot-data name"),
            per_condition: int = typer.Option(1000, help="Valid rows per condition value"),
            seed: int = typer.Option(0),
            condition: list[float] = typer.Option(None, help="Condition values (default: the task's)"),
            strict: bool = typer.Option(False, help="Refuse conditions outside the task's range"),
            output: Path = typer.Option(..., "-o", "--output", help="Dataset .npz to write")):
    """Collect constraint-satisfying configurations (resumes after an interruption)."""
    import time

    from manifoldgen.data import collect as run_collect
    if per_condition <= 0:
        raise ManifoldgenError(f"--per-condition must be positive, got {per_condition}")
    task_obj = _task(task, robot)
    values = _check_conditions(task_obj, condition, strict)
    start = time.perf_counter()
    dataset = run_collect(task_obj, per_condition, seed, output, conditions=values)
    elapsed = time.perf_counter() - start
    console.print(f"wrote {output}: {len(dataset)} rows x {dataset.q.shape[1]} joints "
                  f"({task_obj.robot.name}, {task} task) in {elapsed:.1f} s "
                  f"({len(dataset) / elapsed:,.0f} rows/s)")


@app.command()
@friendly
def tasks():
    """List the named tasks, their robots, planning groups and condition ranges."""
    from manifoldgen.tasks import TASKS, get_task
    for name, robots in TASKS.items():
        for robot in robots:
            t = get_task(name, robot)
            console.print(f"{name:<6} {robot:<9} {t.robot.n:>2} joints  {t.condition.describe()}; training values "
                          f"{', '.join(f'{v:g}' for v in t.condition.values.ravel())}")


@app.command()
@friendly
def demo(output: Path = typer.Option(Path("demo-out"), "-o", "--output", help="Folder for the demo's files"),
         seed: int = typer.Option(0)):
    """The whole pipeline on the embedded default (panda pose task)."""
    from manifoldgen.demo import run_demo
    run_demo(output, seed, console)


@app.command()
@friendly
def plan(task: str = typer.Argument(..., help="Task name, e.g. pose"),
         robot: str = typer.Option("panda", help="example-robot-data name"),
         scene: str = typer.Option(..., help="Named scene (wall, maze) or a scene .json file"),
         sampler: str = typer.Option("project", help="uniform, project, pg:DATASET.npz or MODEL:DIR "
                                     "(e.g. cvae:runs/cvae)"),
         planner: str = typer.Option("rrtconnect", help="rrtconnect, rrt, prm, kpiece, cbirrt"),
         local: str = typer.Option("interpolate", help="Local planner: interpolate or project"),
         seed: int = typer.Option(0),
         time_limit: float = typer.Option(30.0, "--time", help="Planning time limit in seconds"),
         smooth: bool = typer.Option(False, help="Shortcut the path (re-validated) after planning"),
         output: Path = typer.Option(..., "-o", "--output", help="Path .npz to write (a .png is saved beside it)")):
    """Plan the scene's query; writes the path (.npz) and its picture (.png). Exit 1 when unsolved."""
    import torch

    from manifoldgen.planning.query import run_query, save_path
    from manifoldgen.scene import get_scene
    from manifoldgen.viz.path import plot_path
    torch.set_num_threads(1)
    task_obj = _task(task, robot)
    scene_obj = get_scene(task_obj, scene)
    result, meta = run_query(task_obj, scene_obj, sampler, planner, seed=seed, time_limit=time_limit,
                             local=local, smooth=smooth)
    save_path(output, result, meta)
    picture = output.with_suffix(".png")
    plot_path(result.path, task_obj.robot, meta["constraint"].get("frame", task_obj.robot.model.frames[-1].name),
              scene_obj, picture, f"{scene_obj.name}: {planner} + {sampler}, seed {seed}")
    status = "[green]solved[/]" if result.solved else "[red]not solved[/]"
    console.print(f"{status} in {result.time_s:.3f} s | length {result.length:.2f} rad | {len(result.path)} "
                  f"waypoints | {result.samples_drawn} samples, {result.iterations} iterations -> {output}, {picture}")
    if not result.solved:
        raise typer.Exit(1)


@app.command()
@friendly
def train(dataset: Path = typer.Argument(..., help="Dataset .npz made by `manifoldgen collect`"),
          model: str = typer.Option("cvae", "--model", help="Model name: cvae, cgan, wgan, flow"),
          seed: int = typer.Option(0),
          output: Path = typer.Option(..., "-o", "--output", help="Model directory to write"),
          epochs: int = typer.Option(None, help="Maximum epochs (default: the model's)"),
          resume: bool = typer.Option(False, help="Continue an interrupted run from its checkpoint"),
          threads: int = typer.Option(1, help="torch CPU threads (one is as fast for these small MLPs and never spins against other processes)")):
    """Train a conditional generative model (checkpoints every epoch; --resume continues)."""
    import torch

    from manifoldgen.data import Dataset
    from manifoldgen.models import get_model_class
    torch.set_num_threads(max(1, threads))
    net = get_model_class(model)()
    log = net.fit(Dataset.load(dataset), epochs=epochs, seed=seed, out=output, resume=resume)
    console.print(f"trained {model} on {dataset}: {len(log.history)} epochs in {log.seconds:.0f} s, best epoch "
                  f"{log.best_epoch} (validation {log.best_val:.4g}{', stopped early' if log.stopped_early else ''}) "
                  f"-> {output} (model.json, model.safetensors, loss.png)")


@app.command()
@friendly
def sample(model_dir: Path = typer.Argument(..., help="Model directory made by `manifoldgen train`"),
           condition: list[float] = typer.Option(..., help="Condition value(s) y, e.g. --condition 0.45"),
           n: int = typer.Option(1000, "-n", help="Number of samples"),
           seed: int = typer.Option(0),
           refine: int = typer.Option(0, help="Max projection iterations per sample (0: raw rows)"),
           strict: bool = typer.Option(False, help="Refuse conditions outside the trained range"),
           task: str = typer.Option(None, help="Task to check against (default: the model's)"),
           robot: str = typer.Option(None, help="Robot of --task (default: the model's)"),
           output: Path = typer.Option(..., "-o", "--output", help="Samples .npz (dataset format)")):
    """Generate configurations with a trained model; prints raw and refined within-tolerance rates."""
    import torch

    from manifoldgen.models import load_model
    from manifoldgen.sampling import check_model_matches, sample_to_file
    torch.set_num_threads(2)
    if n <= 0:
        raise ManifoldgenError(f"-n must be a positive number of samples, got {n}")
    net = load_model(model_dir)
    task_obj = _task(task or net.meta.get("task", "pose"), robot or net.meta["robot"])
    check_model_matches(net, task_obj.constraint)
    y = net.check_condition([condition], strict=strict)[0]
    info = sample_to_file(net, task_obj.constraint, y, n, output, seed=seed, refine=refine, source=str(model_dir))
    console.print(f"wrote {output}: {n} {info['rows']} rows at {y.tolist()} | within tolerance: raw "
                  f"{info['raw_valid_rate']:.2%}, after refine {refine}: {info['refined_valid_rate']:.2%}")


@bench_app.command("sampling")
@friendly
def bench_sampling(model_dirs: list[Path] = typer.Argument(..., help="Trained model directories"),
                   output: Path = typer.Option(..., "-o", "--output", help="Folder for JSON, Markdown, PNGs"),
                   samples: int = typer.Option(3000, help="Samples per condition for accuracy/coverage"),
                   refine: int = typer.Option(3, help="LM iterations for the refined rate"),
                   reference: int = typer.Option(3000, help="Reference projection samples per condition"),
                   repeats: int = typer.Option(7, help="Timing repeats (median)"),
                   threads: int = typer.Option(2, help="torch CPU threads for sampling"),
                   seed: int = typer.Option(0)):
    """Table I: sampling time for 100..100k rows, accuracy and coverage per model."""
    import torch

    from manifoldgen.bench.sampling import run_sampling_bench
    torch.set_num_threads(max(1, threads))
    run_sampling_bench(model_dirs, output, samples=samples, refine=refine, reference_rows=reference,
                       repeats=repeats, seed=seed, threads=max(1, threads))
    console.print((output / "table.md").read_text())
    console.print(f"wrote {output}/results.json, table.md, fig2_samples.png, residuals.png, coverage.png")


def _bench_planning(scene: str, runs: int | None, workers: int, time_limit: float | None, output: Path,
                    methods: list[str] | None, models: list[Path] | None, resume: bool, seed: int, pg_rows: int,
                    baseline: str | None, task: str, robot: str) -> None:
    from manifoldgen.bench.planning import PAPER_LIMITS, Experiment, default_baseline, default_methods, run_bench
    paper = PAPER_LIMITS[scene]
    experiment = Experiment(scene, task, robot, paper["time_limit"] if time_limit is None else time_limit, seed)
    methods = methods or default_methods(models or None)
    table, _ = run_bench(experiment, methods, output, runs=paper["runs"] if runs is None else runs,
                         workers=workers, resume=resume, pg_rows=pg_rows,
                         baseline=baseline or default_baseline(methods))
    console.print(table)
    console.print(f"wrote {output}/runs.jsonl, results.md, time.png, length.png")


_METHODS_HELP = ("LABEL=PLANNER:LOCAL@SAMPLER (label, local planner and sampler optional), repeatable, e.g. "
                 "cvae=rrtconnect:interpolate@cvae:DIR, "
                 "pg=rrtconnect@pg, cbirrt@uniform, ompl-projected-rrtconnect, ompl-joint-prm@cvae:DIR "
                 "(default: the shipped model, PG, CBiRRT, OMPL Projected/Atlas/TangentBundle, uniform)")


@bench_app.command("wall")
@friendly
def bench_wall(runs: int = typer.Option(None, help="Runs per method (default: the paper's 1000)"),
               workers: int = typer.Option(1, help="Parallel worker processes"),
               time_limit: float = typer.Option(None, "--time", help="Seconds per run (default 200)"),
               output: Path = typer.Option(..., "-o", "--output", help="Folder for runs.jsonl, results.md, PNGs"),
               methods: list[str] = typer.Option(None, "--methods", "-m", help=_METHODS_HELP),
               model: list[Path] = typer.Option(None, "--model", help="Trained model dirs for the default "
                                                "methods (repeatable; default: the shipped model)"),
               resume: bool = typer.Option(False, help="Continue the runs already in the output folder"),
               seed: int = typer.Option(0, help="Run r uses seed + r"),
               pg_rows: int = typer.Option(10_000, help="PG dataset rows at the scene's condition"),
               baseline: str = typer.Option(None, help="Method label for the speed-up column"),
               task: str = typer.Option("pose"), robot: str = typer.Option("panda")):
    """Table II: the wall scene, every method on the same query and seeds."""
    _bench_planning("wall", runs, workers, time_limit, output, methods, model, resume, seed, pg_rows, baseline,
                    task, robot)


@bench_app.command("maze")
@friendly
def bench_maze(runs: int = typer.Option(None, help="Runs per method (default: the paper's 100)"),
               workers: int = typer.Option(1, help="Parallel worker processes"),
               time_limit: float = typer.Option(None, "--time", help="Seconds per run (default: the paper's 200)"),
               output: Path = typer.Option(..., "-o", "--output", help="Folder for runs.jsonl, results.md, PNGs"),
               methods: list[str] = typer.Option(None, "--methods", "-m", help=_METHODS_HELP),
               model: list[Path] = typer.Option(None, "--model", help="Trained model dirs for the default "
                                                "methods (repeatable; default: the shipped model)"),
               resume: bool = typer.Option(False, help="Continue the runs already in the output folder"),
               seed: int = typer.Option(0, help="Run r uses seed + r"),
               pg_rows: int = typer.Option(10_000, help="PG dataset rows at the scene's condition"),
               baseline: str = typer.Option(None, help="Method label for the speed-up column"),
               task: str = typer.Option("pose"), robot: str = typer.Option("panda")):
    """Table III: the maze scene (tool in hand), every method on the same query and seeds."""
    _bench_planning("maze", runs, workers, time_limit, output, methods, model, resume, seed, pg_rows, baseline,
                    task, robot)
