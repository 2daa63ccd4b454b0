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
def demo(output: Path = typer.Option(Path("demo-out"), "-o", "--output", help="Folder for the demo's files"),
         seed: int = typer.Option(0)):
    """The whole pipeline on the embedded default (panda pose task)."""
    from manifoldgen.demo import run_demo
    run_demo(output, seed, console)


def _bench_planning(scene: str, runs: int | None, workers: int, time_limit: float | None, output: Path,
                    methods: list[str] | None, resume: bool, seed: int, pg_rows: int, baseline: str | None,
                    task: str, robot: str) -> None:
    from manifoldgen.bench.planning import PAPER_LIMITS, Experiment, default_baseline, default_methods, run_bench
    paper = PAPER_LIMITS[scene]
    experiment = Experiment(scene, task, robot, paper["time_limit"] if time_limit is None else time_limit, seed)
    methods = methods or default_methods()
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
               resume: bool = typer.Option(False, help="Continue the runs already in the output folder"),
               seed: int = typer.Option(0, help="Run r uses seed + r"),
               pg_rows: int = typer.Option(10_000, help="PG dataset rows at the scene's condition"),
               baseline: str = typer.Option(None, help="Method label for the speed-up column"),
               task: str = typer.Option("pose"), robot: str = typer.Option("panda")):
    """Table II: the wall scene, every method on the same query and seeds."""
    _bench_planning("wall", runs, workers, time_limit, output, methods, resume, seed, pg_rows, baseline, task, robot)


@bench_app.command("maze")
@friendly
def bench_maze(runs: int = typer.Option(None, help="Runs per method (default: the paper's 100)"),
               workers: int = typer.Option(1, help="Parallel worker processes"),
               time_limit: float = typer.Option(None, "--time", help="Seconds per run (default: the paper's 200)"),
               output: Path = typer.Option(..., "-o", "--output", help="Folder for runs.jsonl, results.md, PNGs"),
               methods: list[str] = typer.Option(None, "--methods", "-m", help=_METHODS_HELP),
               resume: bool = typer.Option(False, help="Continue the runs already in the output folder"),
               seed: int = typer.Option(0, help="Run r uses seed + r"),
               pg_rows: int = typer.Option(10_000, help="PG dataset rows at the scene's condition"),
               baseline: str = typer.Option(None, help="Method label for the speed-up column"),
               task: str = typer.Option("pose"), robot: str = typer.Option("panda")):
    """Table III: the maze scene (tool in hand), every method on the same query and seeds."""
    _bench_planning("maze", runs, workers, time_limit, output, methods, resume, seed, pg_rows, baseline, task, robot)
