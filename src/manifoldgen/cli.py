"""The ``manifoldgen`` command line: a thin typer layer over the library."""

from __future__ import annotations

from pathlib import Path

import typer

from manifoldgen.cli_common import (MADE_FOR_HELP, ROBOT_HELP, TASK_HELP, TRUST_HELP, app, console, friendly,
                                    load_task, made_for)  # the first of ours: it limits the thread pools
from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import check_output_path
from manifoldgen.runtime import CANDIDATES, MAX_THREADS, REFINE, TORCH_THREADS, set_threads

bench_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None, help="Experiments behind the paper's tables.")
app.add_typer(bench_app, name="bench")


CLUSTER_HELP = ("Run on a Ray cluster: ray (the Ray running on this machine, else one started for the command) or "
                "ray:ADDRESS (a running cluster: its head's HOST:PORT, or auto); needs the [ray] extra; see "
                "docs/cluster.md")
WORKERS_HELP = "Parallel worker processes (default 1); with --cluster: runs at once (default: one per cluster CPU)"
RANGES = {"--time": (1e-3, 86_400.0), "--runs": (1, 100_000), "--threads": (1, MAX_THREADS), "--refine": (0, 1000),
          "--epochs": (1, 100_000), "--settle": (0.0, 600.0), "--hold": (0.0, 600.0), "--duration-scale": (0.01, 100.0),
          "--friction": (0.01, 10.0), "--tilt": (0.1, 45.0)}  # inclusive


DEMO_FILES = ("pose.npz", "dualarm.npz", "balance.npz", "model", "cvae", "wall-", "reach-", "tray-over")  # and
# what collect and train keep beside them (.partial, .lock)


def _bounded(option: str, value):
    """``value`` of ``option`` when inside its :data:`RANGES` entry (None passes: the default), else a one-line error."""
    low, high = RANGES[option]
    if value is not None and not low <= value <= high:
        raise ManifoldgenError(f"{option} must be from {low:g} to {high:g}, got {value!r}" if isinstance(value, float)
                               else f"{option} must be from {low} to {high}, got {value}")
    return value


def _names(registry: str) -> str:
    """The package's own names in a registry (``models`` or ``planners``) for --help, and where others come from."""
    if registry == "models":
        from manifoldgen.models import MODELS as found
    else:
        from manifoldgen.planning import PLANNERS as found
    return f"{', '.join(found.names(announced=False))} (or one an installed package announces)"


def _file(name: str | None) -> Path | None:
    """``name`` as a Path when it names an existing file or folder (an input that outputs must not touch)."""
    return Path(name) if name and Path(name).exists() else None


def _check_conditions(task_obj, condition: list[float] | None, strict: bool):
    if condition is None:
        return None
    return task_obj.condition.check([[v] for v in condition] if task_obj.condition.k == 1 else [condition],
                                    strict=strict)


@app.command()
@friendly
def collect(task: str = typer.Argument(..., help=TASK_HELP),
            robot: str = typer.Option(None, help=ROBOT_HELP),
            per_condition: int = typer.Option(None, help="Valid rows per condition value (default: 10,000 rows "
                                              "shared by the condition values, at least 200 each)"),
            seed: int = typer.Option(0),
            condition: list[float] = typer.Option(None, help="Condition values (default: the task's)"),
            strict: bool = typer.Option(False, help="Refuse conditions outside the task's range"),
            anchors: bool = typer.Option(True, help="Seed half the rows around the start and goal of the task's "
                                         "scenes (their IK branches); --no-anchors: uniform seeds only"),
            near_home: float = typer.Option(0.0, help="Seeds normal around the task's home with this standard "
                                            "deviation (rad) instead: rows on the home's IK branch (0: as above)"),
            cluster: str = typer.Option(None, help=CLUSTER_HELP),
            output: Path = typer.Option(..., "-o", "--output", help="Dataset .npz to write")):
    """Collect constraint-satisfying configurations (resumes after an interruption) and report the modes (IK
    branches) they fall in and how near they come to every scene's start and goal."""
    import time

    from manifoldgen.cluster import parse_cluster
    from manifoldgen.data import collect as run_collect, default_rows
    from manifoldgen.scene import task_anchors
    if per_condition is not None and per_condition <= 0:
        raise ManifoldgenError(f"--per-condition must be positive, got {per_condition}")
    on = parse_cluster(cluster)
    check_output_path(output, [_file(task)], suffixes=(".npz",), kind="dataset")
    task_obj = load_task(task, robot)
    values = _check_conditions(task_obj, condition, strict)
    set_threads()
    start = time.perf_counter()
    found = task_anchors(task_obj) if anchors and not near_home else None
    if per_condition is None:
        per_condition = default_rows(len(task_obj.condition.grid) if values is None else len(values))
    dataset = run_collect(task_obj, per_condition, seed, output, conditions=values, near_home=near_home,
                          anchors=found, cluster=on)
    elapsed = time.perf_counter() - start
    console.print(f"wrote {output}: {len(dataset)} rows x {dataset.q.shape[1]} joints "
                  f"({task_obj.robot.name}, {task_obj.name} task) in {elapsed:.1f} s "
                  f"({len(dataset) / elapsed:,.0f} rows/s)")
    console.print(_coverage_lines(dataset.meta["coverage"]), markup=False, highlight=False)


def _coverage_lines(report: dict) -> str:
    """The collection's coverage report (:func:`manifoldgen.data.coverage`) as a few lines."""
    counts = [len(shares) for shares in report["modes"].values()]
    lines = [f"modes (IK branches) per condition: {min(counts)}-{max(counts)}" if min(counts) != max(counts)
             else f"modes (IK branches) per condition: {counts[0]}"]
    for value, shares in report["modes"].items():
        if len(shares) > 1:
            lines.append(f"  at {value}: " + ", ".join(f"{s:.0%}" for s in shares) + " of the rows")
    from manifoldgen.coverage import gap_lines
    lines += gap_lines(report.get("anchors", []), "row")
    if any(a["missed"] for a in report.get("anchors", [])):
        lines.append("no row comes near a MISSED start or goal: collect more rows (--per-condition), or check that "
                     "the scene's condition is among the collected ones")
    return "\n".join(lines)


def _model_gap_lines(net, seed: int) -> str:
    """For every scene start and goal the model's dataset recorded: how near the model's samples come."""
    import torch

    from manifoldgen.coverage import anchors_from_meta, gap_lines, model_gaps
    anchors = anchors_from_meta(net.meta)
    if anchors is None:
        return ""
    report = model_gaps(lambda y, n: net.sample(y, n, torch.Generator().manual_seed(seed)), anchors)
    lines = gap_lines(report, "sample")
    if any(r["missed"] for r in report):
        lines.append("the model misses a MISSED start or goal (an IK branch): planning there falls back to projected "
                     "uniform samples; train another model (--model cfm) or with more epochs")
    return "\n".join(lines)


@app.command()
@friendly
def tasks(files: list[str] = typer.Argument(None, help="Task .toml files to describe (default: the built-in "
                                             "tasks); a file naming a module:Class constraint imports, i.e. runs, "
                                             "that module")):
    """List tasks: robot, planning group size, condition range, training values and scenes."""
    from manifoldgen.tasks import builtin_tasks, get_task
    entries = [(f, None) for f in files] if files else [(n, r) for n, robots in builtin_tasks().items() for r in robots]
    for name, robot in entries:
        t = get_task(name, robot)
        values = "; ".join(", ".join(f"{v:g}" for v in row) for row in t.condition.grid) or "none"
        console.print(f"{t.name:<8} {t.robot.name:<9} {t.robot.n:>2} joints  {t.condition.describe() or 'unconditioned'}"
                      f"; training values {values}; scenes: {', '.join(t.scenes) or 'none'}", markup=False)


@app.command()
@friendly
def robots(robot: str = typer.Argument(None, help="A robot name or URDF path to describe (default: list the names)"),
           srdf: Path = typer.Option(None, help="SRDF for a URDF path (default: the one beside it)")):
    """List the robots that load by name, or describe one: joints, limits, frames, SRDF and URDF hash."""
    from manifoldgen.robot import Robot, known_robots
    if robot is None:
        if srdf is not None:
            raise ManifoldgenError("--srdf goes with a robot to describe: give its name or URDF path too")
        console.print(", ".join(known_robots()), markup=False)
        return
    r = Robot.load(robot, srdf=srdf)
    console.print(f"{r.name}: URDF {r.urdf_path} (sha256 {r.identity['urdf_sha256'][:12]}), SRDF {r.srdf or 'none'}",
                  markup=False)
    for joint, lo, hi in zip(r.joints, r.lower, r.upper):
        console.print(f"  {joint:<28} [{lo:+.3f}, {hi:+.3f}]", markup=False)
    console.print(f"  frames: {', '.join(f.name for f in r.model.frames[1:])}", markup=False)


@app.command()
@friendly
def demo(name: str = typer.Argument("pose", help="Which experiment: pose (panda, wall scene), dualarm (pr2 "
                                     "carries a tray over a block), balance (centauro, reach scene)"),
         output: Path = typer.Option(Path("demo-out"), "-o", "--output", help="Folder for the demo's files"),
         seed: int = typer.Option(0)):
    """The whole pipeline for one experiment on its embedded default (default: the panda pose task)."""
    from manifoldgen.demos import run
    check_output_path(output, directory=True)
    foreign = sorted(p.name for p in output.iterdir() if not p.name.startswith(DEMO_FILES)) if output.is_dir() else []
    if foreign:
        raise ManifoldgenError(f"-o {output} holds files no demo wrote ({', '.join(foreign[:3])}"
                               f"{', ...' if len(foreign) > 3 else ''}); a demo writes its dataset and model among "
                               "them: give a new or empty folder (or a demo's own, to resume it)")
    run(name, output, seed, console)


def _roadmap_line(roadmap: Path, result) -> str:
    """What ``plan --roadmap`` did with the file: routed or not, its nodes, written or not, what it dropped."""
    held = result.extras["roadmap"]
    fate = " saved" if held["written"] else ", unchanged" if result.solved else ", the file not written"
    dropped = held["dropped"]
    lost = (f"; dropped {dropped['nodes']} nodes and {dropped['edges']} edges read from it that failed the check"
            if any(dropped.values()) else "")
    return f"roadmap {roadmap}: {'routed through it' if held['routed'] else 'not routed'}; {held['nodes']} nodes{fate}{lost}"


@app.command()
@friendly
def plan(task: str = typer.Argument(..., help=TASK_HELP),
         robot: str = typer.Option(None, help=ROBOT_HELP),
         scene: str = typer.Option(..., help="Named scene (wall, maze) or a scene .json file"),
         sampler: str = typer.Option("project", help="uniform, project, pg:DATASET.npz or MODEL:DIR "
                                     "(e.g. cvae:runs/cvae)"),
         planner: str = typer.Option("rrtconnect", help=f"Planner: {_names('planners')}"),
         local: str = typer.Option("auto", help="Local planner: auto (straight segments, projected walks where "
                                   "they leave the manifold), interpolate or project"),
         seed: int = typer.Option(0),
         time_limit: float = typer.Option(30.0, "--time", help="Planning time limit in seconds"),
         smooth: bool = typer.Option(False, help="Shorten the path within the query (shortcut attempts, each stretch "
                                     "checked densely); the same as --set shortcut=50"),
         settings: list[str] = typer.Option(None, "--set", help="Planner setting KEY=VALUE (repeatable), e.g. "
                                            "--set range=0.8; unknown keys list the known ones"),
         config: Path = typer.Option(None, help="TOML file of planner settings (--set wins)"),
         snapshots: Path = typer.Option(None, help="Also write a PNG strip of robot snapshots along the path (t0..t5)"),
         picture: bool = typer.Option(True, "--picture/--no-picture", help="Draw the path's picture (a .png beside "
                                      "-o; matplotlib takes 1-2 s of the command's time)"),
         roadmap: Path = typer.Option(None, help="Roadmap .npz of earlier paths in this task, condition and scene "
                                      "(planner setting reuse=true): the query is routed through it first when the "
                                      "file exists, and a solved query writes it back with its path"),
         output: Path = typer.Option(..., "-o", "--output", help="Path .npz to write (a .png is saved beside it)")):
    """Plan the scene's query; writes the path (.npz) and its picture (.png, unless --no-picture). Exit 1 when
    unsolved (nothing written)."""
    from manifoldgen.planning import planner_settings
    from manifoldgen.planning.result import engine
    from manifoldgen.query import run_query, save_path
    from manifoldgen.runtime import set_threads
    from manifoldgen.scene import get_scene
    from manifoldgen.settings import parse_settings
    from manifoldgen.targets import constrained_frame
    from manifoldgen.specs import parse_spec
    set_threads()
    _bounded("--time", time_limit)
    image = output.with_suffix(".png") if picture else None
    if image == output or (snapshots is not None and snapshots in (output, image)):
        also = f" and --snapshots {snapshots}" if snapshots else ""
        raise ManifoldgenError(f"-o {output} and its picture {image or output.with_suffix('.png')}{also} would "
                               "overwrite each other; give -o a .npz name and --snapshots another .png")
    if image is not None and image.is_dir():
        raise ManifoldgenError(f"the path's picture {image} (the .png beside -o {output}) is a folder; give -o "
                               "another name, or pass --no-picture")
    inputs = [_file(task), _file(scene), _file(parse_spec(sampler)[1]), config]
    roadmap_file = roadmap.resolve() if roadmap is not None else None  # a link: the file it names, written through
    clash = next((out for out in (output, image, snapshots) if roadmap_file is not None and out is not None
                  and roadmap_file == out.resolve()), None)
    if clash is not None:
        raise ManifoldgenError(f"--roadmap {roadmap} is also the output {clash} of this command; give the roadmap "
                               "a file of its own (e.g. roadmap.npz)")
    if roadmap_file is not None:  # read and checked before it is replaced
        check_output_path(roadmap_file, inputs, what="--roadmap" if roadmap_file == roadmap.absolute()
                          else f"--roadmap {roadmap} ->", suffixes=(".npz",), owned=False)
    for out, what, suffix, kind in ((output, "-o", ".npz", "path"), (image, "-o's picture", ".png", None),
                                    (snapshots, "--snapshots", ".png", None)):
        if out is not None:
            check_output_path(out, inputs, what=what, suffixes=(suffix,), kind=kind)
    values = parse_settings(settings, config, planner_settings(planner), f"{planner} planner")
    if smooth and values.get("shortcut") == 0:
        raise ManifoldgenError("--smooth asks for shortcut attempts, but shortcut=0 (from --set or --config) allows "
                               "none; leave out one of them")
    task_obj = load_task(task, robot)
    scene_obj = get_scene(task_obj, scene)
    result, meta = run_query(task_obj, scene_obj, sampler, planner, seed=seed, time_limit=time_limit,
                             local=local, smooth=smooth, settings=values, roadmap=roadmap_file)
    routed = _roadmap_line(roadmap, result) if roadmap is not None else ""
    if not result.solved:  # no path: nothing is written, so no file can pass for one
        console.print(f"[red]not solved[/] in {result.time_s:.3f} s | {result.samples_drawn} samples, "
                      f"{result.iterations} iterations | {engine(result.extras)} | nothing written")
        console.print(result.why(), markup=False)
        if routed:
            console.print(routed, markup=False, highlight=False)
        raise typer.Exit(1)
    save_path(output, result, meta)
    written = [output]
    if image is not None:
        from manifoldgen.viz.path import plot_path
        frame = (scene_obj.targets.get("goal") or scene_obj.targets.get("start") or {}).get("frame") \
            or constrained_frame(task_obj.constraint) or task_obj.robot.model.frames[-1].name  # a reach: its hand
        plot_path(result.path, task_obj.robot, frame, scene_obj, image,
                  f"{scene_obj.name}: {planner} + {sampler}, seed {seed}")
        written.append(image)
    if snapshots is not None:
        from manifoldgen.viz.snapshots import draw_snapshots
        draw_snapshots(result.path, task_obj, scene_obj, snapshots)
        written.append(snapshots)
    console.print(f"[green]solved[/] in {result.time_s:.3f} s | length {result.length:.2f} rad | {len(result.path)} "
                  f"waypoints | {result.samples_drawn} samples, {result.iterations} iterations | {engine(result.extras)} "
                  f"-> {', '.join(map(str, written))}")
    if routed:
        console.print(routed, markup=False, highlight=False)
    if result.extras.get("sampler_note"):
        console.print(f"note: {result.extras['sampler_note']}", markup=False)


@app.command()
@friendly
def physics(path: Path = typer.Argument(..., help="Path .npz of a floating-base robot (a balance task's path)"),
            duration_scale: float = typer.Option(1.0, help="Divides the speed limits (0.5 rad/s per joint, 0.1 m/s "
                                                 "for the base); the acceleration limits (1 rad/s², 0.1 m/s²) stay, "
                                                 "so a segment they pace keeps its duration: below 1 it often "
                                                 "changes nothing (a warning says so)"),
            settle: float = typer.Option(0.5, help="Seconds holding the first state before moving"),
            hold: float = typer.Option(1.0, help="Seconds holding the last state"),
            friction: float = typer.Option(0.8, help="Foot-ground sliding friction coefficient"),
            tilt: float = typer.Option(10.0, help="Upright: max base tilt from the plan, degrees"),
            feet: list[str] = typer.Option(None, "--feet", help="Foot frames (default: the balance constraint's)"),
            output: Path = typer.Option(None, "-o", "--output", help="Also write the report as JSON"),
            task: str = typer.Option(None, help=MADE_FOR_HELP),
            trust_code: bool = typer.Option(False, "--trust-code", help=TRUST_HELP)):
    """Execute the path quasi-statically in MuJoCo (feet on the ground, base free, joints servoed): upright?"""
    from manifoldgen.io import atomic_write_text, check_output_path
    from manifoldgen.physics import PhysicsSettings, check_path_file, summary, to_json
    for option, value in (("--settle", settle), ("--hold", hold), ("--duration-scale", duration_scale),
                          ("--friction", friction), ("--tilt", tilt)):
        _bounded(option, value)
    pace = PhysicsSettings()
    settings = PhysicsSettings(seconds_per_rad=pace.seconds_per_rad * duration_scale,
                               seconds_per_m=pace.seconds_per_m * duration_scale, settle_s=settle, hold_s=hold,
                               friction=friction, tilt_threshold_deg=tilt)
    if output is not None:
        check_output_path(output, [path], suffixes=(".json",), kind="physics")
    result = check_path_file(path, settings, feet=feet, progress=True, task=made_for(task), trust_code=trust_code)
    if duration_scale != 1.0:
        _warn_same_pace(path, settings, pace, duration_scale)
    console.print(summary(result), markup=False, highlight=False)
    if output is not None:
        atomic_write_text(output, to_json(result))


def _warn_same_pace(path_file: Path, settings, default, duration_scale: float) -> None:
    """Warn when ``--duration-scale`` leaves the path's motion as long as without it: the acceleration limits,
    which it does not scale, pace every segment."""
    import warnings

    from manifoldgen.io import load_npz
    from manifoldgen.physics.simulate import schedule
    path = load_npz(path_file, ("path",))[1]["path"]
    if schedule(path, settings)[1] == schedule(path, default)[1]:
        warnings.warn(f"--duration-scale {duration_scale:g} changes nothing for this path: the acceleration limits, "
                      "which it does not scale, pace every segment (physics.md, Time)", stacklevel=2)


@app.command()
@friendly
def train(dataset: Path = typer.Argument(..., help="Dataset .npz made by `manifoldgen collect`"),
          model: str = typer.Option("auto", "--model", help=f"Model: auto (train {', '.join(CANDIDATES)} and keep the "
                                    f"best on held-out rows), {_names('models')}, or module:Class"),
          settings: list[str] = typer.Option(None, "--set", help="Hyper-parameter KEY=VALUE (repeatable), e.g. "
                                             "--set latent=8 --set 'hidden=[128,128]'"),
          config: Path = typer.Option(None, help="TOML file of hyper-parameters (--set wins)"),
          seed: int = typer.Option(0),
          output: Path = typer.Option(..., "-o", "--output", help="Model directory to write"),
          epochs: int = typer.Option(None, help="Maximum epochs (default: the model's)"),
          resume: bool = typer.Option(False, help="Continue an interrupted run from its checkpoint"),
          threads: int = typer.Option(TORCH_THREADS, help="torch CPU threads (one is as fast for these small MLPs "
                                      "and never spins against other processes)"),
          task: str = typer.Option(None, help=MADE_FOR_HELP),
          trust_code: bool = typer.Option(False, "--trust-code", help=TRUST_HELP)):
    """Train a conditional generative model (checkpoints every epoch; --resume continues). Sizes not set are
    taken from the data (latent: the manifold's dimension; width: from the joint count)."""
    from manifoldgen.dataset import Dataset
    from manifoldgen.models import get_model_class
    from manifoldgen.selection import SELECTION_FILE, check_recorded_scenes, select_model
    from manifoldgen.settings import parse_settings
    from manifoldgen.tasks import task_from_meta
    from manifoldgen.training import OUTPUT_FILES
    check_output_path(output, [dataset, config, _file(task)], directory=True,
                      writes=OUTPUT_FILES + (SELECTION_FILE, "candidates"))
    if model == "auto" and (settings or config):
        raise ManifoldgenError("--set and --config set one model's hyper-parameters; name it with --model (e.g. "
                               "--model cvae)")
    set_threads(_bounded("--threads", threads))
    _bounded("--epochs", epochs)
    data = Dataset.load(dataset)
    task_obj = task_from_meta(data.meta, task=made_for(task), trust_code=trust_code, what=f"dataset {dataset}")
    if model == "auto":
        net, table, raced = select_model(data, output, seed=seed, epochs=epochs, resume=resume, task=task_obj)
        for row in table:
            verdict = ("kept  " if raced else "chosen") if row["chosen"] else "tried "  # raced: the race chooses
            diverged = (f" (diverged at epoch {row['diverged_at']}: epoch {row['best_epoch']} kept)"
                        if row.get("diverged_at") else "")
            made = (f"{row['blend']:.0%} of its rows from the second" if "blend" in row else
                    f"{row['epochs']} epochs in {row['seconds']:.0f} s{diverged}")
            console.print(f"{verdict} {row['model']}: {made}; on held-out rows {row['accuracy']:.1%} of raw samples "
                          f"within tolerance, recall {row['recall']:.2f}", markup=False)
        for row in raced:
            console.print(f"{'chosen' if row['chosen'] else 'raced '} {row['label']} on the task's scenes: "
                          f"{row['solved']}/{row['runs']} solved, median CPU {row['cpu']:.3f} s", markup=False)
        if raced and net.mix == 1.0:
            console.print("plain projection planned this task's scenes fastest: the model directory's sampler is the "
                          "projection sampler (see selection.json)", markup=False)
        console.print(f"trained {net.label} on {dataset} -> {output} (model.json, model.safetensors, loss.png, "
                      f"{SELECTION_FILE}, candidates/{', blend/' if net.blend else ''})")
    else:
        cls = get_model_class(model)
        net = cls(**parse_settings(settings, config, cls.defaults, f"{model} model"))
        check_recorded_scenes(data)  # the model keeps them in its meta: read whole before training
        log = net.fit(data, epochs=epochs, seed=seed, out=output, resume=resume, task=task_obj)
        console.print(f"trained {model} on {dataset}: {len(log.history)} epochs in {log.seconds:.0f} s, best epoch "
                      f"{log.best_epoch} (validation {log.best_val:.4g}{', stopped early' if log.stopped_early else ''}"
                      f"{f', diverged at epoch {log.diverged_at}' if log.diverged_at else ''}"
                      f") -> {output} (model.json, model.safetensors, loss.png)")
    gaps = _model_gap_lines(net, seed)
    if gaps:
        console.print(gaps, markup=False, highlight=False)


@app.command()
@friendly
def sample(model_dir: Path = typer.Argument(..., help="Model directory made by `manifoldgen train`"),
           condition: list[float] = typer.Option(..., help="Condition value(s) y, e.g. --condition 0.45"),
           n: int = typer.Option(1000, "-n", help="Number of samples"),
           seed: int = typer.Option(0),
           refine: int = typer.Option(REFINE, help="Max projection iterations per written sample (0: raw rows; "
                                      "the raw rate is printed either way)"),
           strict: bool = typer.Option(False, help="Refuse conditions outside the trained range"),
           task: str = typer.Option(None, help="Task to check against (default: the model's own, from its file; "
                                    "needed for a user's module:Class constraint): " + TASK_HELP),
           robot: str = typer.Option(None, help=ROBOT_HELP),
           trust_code: bool = typer.Option(False, "--trust-code", help=TRUST_HELP),
           output: Path = typer.Option(..., "-o", "--output", help="Samples .npz (dataset format)")):
    """Generate configurations with a trained model; prints raw and refined within-tolerance rates."""
    from manifoldgen.models import load_model
    from manifoldgen.sampling import sample_to_file
    from manifoldgen.tasks import task_from_meta
    set_threads(2)
    _bounded("--refine", refine)
    if robot is not None and task is None:
        raise ManifoldgenError("--robot picks the robot of a built-in --task; give --task too (the model's own "
                               "task and robot are used without both)")
    net = load_model(model_dir)
    check_output_path(output, [model_dir, _file(task)], suffixes=(".npz",), kind="samples")
    task_obj = task_from_meta(net.meta, task=made_for(task, robot), trust_code=trust_code, what=f"model {model_dir}")
    y = net.check_condition([condition], strict=strict)[0]
    info = sample_to_file(net, task_obj.constraint, y, n, output, seed=seed, refine=refine, source=str(model_dir))
    console.print(f"wrote {output}: {n} {info['rows']} rows at {y.tolist()} | within tolerance: raw "
                  f"{info['raw_valid_rate']:.2%}, after refine {refine}: {info['refined_valid_rate']:.2%}")
    gaps = _model_gap_lines(net, seed)
    if gaps:
        console.print(gaps, markup=False, highlight=False)


def _condition_rows(texts: list[str] | None) -> list[list[float]] | None:
    """``["0.3,0", ...]`` -> ``[[0.3, 0.0], ...]`` (None when none given)."""
    if not texts:
        return None
    try:
        return [[float(v) for v in text.split(",")] for text in texts]
    except ValueError:
        raise ManifoldgenError(f"conditions must be numbers, comma-separated per condition (e.g. 0.3,0); got "
                               f"{texts}") from None


@bench_app.command("sampling")
@friendly
def bench_sampling(model_dirs: list[Path] = typer.Argument(..., help="Trained model directories"),
                   output: Path = typer.Option(..., "-o", "--output", help="Folder for JSON, Markdown, PNGs"),
                   samples: int = typer.Option(3000, help="Samples per condition for accuracy/coverage"),
                   refine: int = typer.Option(REFINE, help="LM iterations for the refined rate"),
                   reference: int = typer.Option(3000, help="Reference projection samples per condition"),
                   repeats: int = typer.Option(7, help="Timing repeats (median)"),
                   threads: int = typer.Option(2, help="torch CPU threads for sampling"),
                   seen: list[str] = typer.Option(None, help="Seen conditions to score (repeatable; k values "
                                                  "comma-separated, e.g. 0.3,0; default: the training values)"),
                   unseen: list[str] = typer.Option(None, help="Unseen conditions to score (repeatable; default: "
                                                    "midpoints and one step past the top); unreachable ones are "
                                                    "skipped with a warning"),
                   seed: int = typer.Option(0),
                   task: str = typer.Option(None, help=MADE_FOR_HELP),
                   trust_code: bool = typer.Option(False, "--trust-code", help=TRUST_HELP)):
    """Table I: sampling time for 100..100k rows, accuracy and coverage per model."""
    from manifoldgen.bench.sampling import OUTPUT_FILES, RESULTS_FILE, run_sampling_bench
    check_output_path(output, [*model_dirs, _file(task)], directory=True, writes=OUTPUT_FILES, markers=(RESULTS_FILE,))
    set_threads(_bounded("--threads", threads))
    run_sampling_bench(model_dirs, output, samples=samples, refine=refine, reference_rows=reference,
                       repeats=repeats, seed=seed, threads=threads, seen=_condition_rows(seen),
                       unseen=_condition_rows(unseen), task=made_for(task), trust_code=trust_code)
    console.print((output / "table.md").read_text())
    console.print(f"wrote {output}/results.json, table.md, fig2_samples.png, residuals.png, coverage.png")


def _bench_planning(scene: str, runs: int | None, workers: int | None, time_limit: float | None, output: Path,
                    methods: list[str] | None, models: list[Path] | None, resume: bool, seed: int, pg_rows: int,
                    baseline: str | None, task: str, robot: str | None, settings: list[str] | None = None,
                    config: Path | None = None, snapshots: bool = False, physics: bool = False,
                    cluster: str | None = None) -> None:
    from manifoldgen.bench.planning import (BENCH_MARKERS, OTHER_LIMITS, OUTPUT_FILES, PAPER_LIMITS, Experiment,
                                            Method, default_baseline, default_methods, run_bench)
    from manifoldgen.cluster import parse_cluster
    from manifoldgen.scene import get_scene
    from manifoldgen.specs import parse_spec
    if methods and models:
        raise ManifoldgenError("--model gives the default methods their model and -m names the methods: with -m, "
                               "name the model in a method (e.g. -m cvae=rrtconnect@cvae:DIR) and leave --model out")
    from manifoldgen.tasks import BUILTIN_DIR
    on = parse_cluster(cluster, workers)
    _bounded("--runs", runs)
    _bounded("--time", time_limit)
    samplers = [Method.parse(m).sampler for m in methods or []]
    check_output_path(output, [_file(task), _file(scene), config, *(models or []),
                               *(_file(parse_spec(s)[1]) for s in samplers if s)],
                      directory=True, writes=OUTPUT_FILES, markers=BENCH_MARKERS)
    task_obj = load_task(task, robot)
    get_scene(task_obj, scene)  # a bad scene fails before any run starts
    builtin = task_obj.file is not None and task_obj.file.parent == BUILTIN_DIR
    paper = PAPER_LIMITS.get(scene, OTHER_LIMITS) if builtin else OTHER_LIMITS
    from manifoldgen.planning import PLANNERS, planner_settings
    from manifoldgen.settings import parse_settings
    from manifoldgen.ompl_settings import benchmark_keys
    known = {**{k: v for name in PLANNERS.names() for k, v in planner_settings(name).items()}, **benchmark_keys()}
    experiment = Experiment(scene, task, task_obj.robot.name if robot is None else robot,
                            paper["time_limit"] if time_limit is None else time_limit, seed,
                            planner_settings=parse_settings(settings, config, known, "planner"), physics=physics)
    if physics and not task_obj.robot.floating_base:
        raise ManifoldgenError(f"--physics executes paths of a robot standing on its feet; {task_obj.robot.name} "
                               f"in task {task_obj.name} has a fixed base: leave --physics out")
    if not methods and not models and not builtin:
        raise ManifoldgenError(f"give --methods or --model for task {task_obj.name}: the shipped model is for the "
                               "panda pose task; e.g. -m rrtconnect@project -m cbirrt@uniform -m cvae=rrtconnect@cvae:DIR")
    methods = methods or default_methods(models or None)
    table, _ = run_bench(experiment, methods, output, runs=paper["runs"] if runs is None else runs,
                         workers=1 if workers is None else workers, resume=resume, pg_rows=pg_rows,
                         baseline=baseline or default_baseline(methods), snapshots=snapshots, cluster=on)
    console.print(table)
    console.print(f"wrote {output}/runs.jsonl, results.md, time.png, length.png")


@bench_app.command("plan")
@friendly
def bench_plan(task: str = typer.Argument(..., help=TASK_HELP),
               scene: str = typer.Option(..., help="A scene the task names, or a scene .json file"),
               robot: str = typer.Option(None, help=ROBOT_HELP),
               runs: int = typer.Option(None, help="Runs per method (default: 20; the paper's counts for wall/maze)"),
               workers: int = typer.Option(None, help=WORKERS_HELP),
               time_limit: float = typer.Option(None, "--time", help="Seconds per run (default 30; 200 for wall/maze)"),
               output: Path = typer.Option(..., "-o", "--output", help="Folder for runs.jsonl, results.md, PNGs"),
               methods: list[str] = typer.Option(None, "--methods", "-m", help="see `bench wall --help`"),
               model: list[Path] = typer.Option(None, "--model", help="Trained model dirs for the default methods"),
               resume: bool = typer.Option(False, help="Continue the runs already in the output folder"),
               seed: int = typer.Option(0, help="Run r uses seed + r"),
               pg_rows: int = typer.Option(10_000, help="PG dataset rows at the scene's condition"),
               baseline: str = typer.Option(None, help="Method label for the speed-up column"),
               settings: list[str] = typer.Option(None, "--set", help="Planner setting KEY=VALUE for our planners "
                                                  "(repeatable; each planner takes those it has; spheres "
                                                  "and shortcut also go to the C++ OMPL baseline; ompl_KEY "
                                                  "to OMPL only, e.g. ompl_range=0.45, ompl_epsilon=0.1)"),
               config: Path = typer.Option(None, help="TOML file of planner settings (--set wins)"),
               snapshots: bool = typer.Option(False, help="Write LABEL-snapshots.png: robot snapshots along each "
                                              "method's run-0 path, when solved"),
               physics: bool = typer.Option(False, help="Balance tasks: execute every solved path quasi-statically "
                                            "in MuJoCo and record whether the robot stays upright"),
               cluster: str = typer.Option(None, help=CLUSTER_HELP)):
    """Any task's scene (a task file's or a scene .json): every method on the same query and seeds."""
    _bench_planning(scene, runs, workers, time_limit, output, methods, model, resume, seed, pg_rows, baseline,
                    task, robot, settings, config, snapshots, physics, cluster)


_METHODS_HELP = ("LABEL=PLANNER:LOCAL@SAMPLER (label, local planner and sampler optional), repeatable, e.g. "
                 "cvae=rrtconnect:interpolate@cvae:DIR, "
                 "pg=rrtconnect@pg, cbirrt@uniform, ompl-projected-rrtconnect, ompl-joint-prm@cvae:DIR; balance "
                 "tasks: rrtconnect:direct@blind (balance-blind), rrtconnect@feet-only (CoM-blind) "
                 "(default: the shipped model, PG, CBiRRT, OMPL Projected/Atlas/TangentBundle, uniform)")


def _paper_scene(scene: str, doc: str, runs_default: str, time_default: str) -> None:
    """Register ``bench SCENE``: one of the paper's panda scenes, every method on the same query and seeds."""
    def command(runs: int = typer.Option(None, help=f"Runs per method (default: {runs_default})"),
                workers: int = typer.Option(None, help=WORKERS_HELP),
                time_limit: float = typer.Option(None, "--time", help=f"Seconds per run (default: {time_default})"),
                output: Path = typer.Option(..., "-o", "--output", help="Folder for runs.jsonl, results.md, PNGs"),
                methods: list[str] = typer.Option(None, "--methods", "-m", help=_METHODS_HELP),
                model: list[Path] = typer.Option(None, "--model", help="Trained model dirs for the default "
                                                 "methods (repeatable; default: the shipped model)"),
                resume: bool = typer.Option(False, help="Continue the runs already in the output folder"),
                seed: int = typer.Option(0, help="Run r uses seed + r"),
                pg_rows: int = typer.Option(10_000, help="PG dataset rows at the scene's condition"),
                baseline: str = typer.Option(None, help="Method label for the speed-up column"),
                task: str = typer.Option("pose", help=TASK_HELP), robot: str = typer.Option(None, help=ROBOT_HELP),
                cluster: str = typer.Option(None, help=CLUSTER_HELP)):
        _bench_planning(scene, runs, workers, time_limit, output, methods, model, resume, seed, pg_rows, baseline,
                        task, robot, cluster=cluster)
    command.__doc__ = doc
    command.__name__ = f"bench_{scene}"
    bench_app.command(scene)(friendly(command))


_paper_scene("wall", "Table II: the wall scene, every method on the same query and seeds.", "the paper's 1000", "200")
_paper_scene("maze", "Table III: the maze scene (tool in hand), every method on the same query and seeds.",
             "the paper's 100", "the paper's 200")


@app.command()
@friendly
def sweep(dataset: Path = typer.Argument(..., help="Dataset .npz made by `manifoldgen collect`"),
          model: list[str] = typer.Option(None, "--model", help=f"Models to train (repeatable; default: "
                                          f"{', '.join(CANDIDATES)}): {_names('models')}"),
          latent: list[int] = typer.Option(None, help="Latent sizes (repeatable; default: the manifold's "
                                           "dimension); models without a latent (cfm, flow) train once per seed"),
          seeds: list[int] = typer.Option(None, "--seed", help="Training seeds (repeatable; default 0)"),
          epochs: int = typer.Option(None, help="Maximum epochs (default: each model's)"),
          cluster: str = typer.Option(None, help=CLUSTER_HELP),
          output: Path = typer.Option(..., "-o", "--output", help="Model directory to write (the best model; "
                                      "candidates/ and sweep.json beside it)")):
    """Train models x latent sizes x seeds (in parallel on --cluster), rank them on held-out rows (accuracy among
    those near the best recall) and write the best as the model directory; sweep.json holds the table. Rerunning
    the same command resumes."""
    from manifoldgen.cluster import parse_cluster
    from manifoldgen.dataset import Dataset
    from manifoldgen.model_sweep import MODEL_FILES, SWEEP_FILE, sweep as run_sweep
    on = parse_cluster(cluster)
    _bounded("--epochs", epochs)
    check_output_path(output, [dataset], directory=True, writes=MODEL_FILES + (SWEEP_FILE, "candidates"))
    set_threads()
    rows = run_sweep(Dataset.load(dataset), output, models=model or list(CANDIDATES), latents=latent or [],
                     seeds=seeds or [0], epochs=epochs, cluster=on)
    for row in rows:
        console.print(f"{row['rank']:>3}. {row['name']}: {row['epochs']} epochs in {row['seconds']:.0f} s; on "
                      f"held-out rows {row['accuracy']:.1%} of raw samples within tolerance, recall "
                      f"{row['recall']:.2f}" + (f" [{row['host']}]" if "host" in row else ""), markup=False)
    console.print(f"best: {rows[0]['name']} -> {output} ({', '.join(MODEL_FILES)}, {SWEEP_FILE}, candidates/)")


from manifoldgen import cli_view  # noqa: E402,F401  (registers view, trajectory)
