"""A user-written constraint trains as well as the built-in constraints of the same kind, and plans in
the compiled core through batched Python callbacks.

    python benchmarks/bench_user_constraint.py [--per-condition 2000] [--epochs 60]
    python benchmarks/bench_user_constraint.py --plan [--runs 10] [--time 30] [--sampler project|cvae]
    python benchmarks/bench_user_constraint.py --jacobians

The same manifold on xarm7, written twice: `examples/user_task/tool_down.py` (a user's ~20-line
constraint, Jacobian and training penalty from its one residual) and the built-in orientation + plane
constraints (`tool-down-xarm7-builtin.toml`). Same data size, seeds and CVAE settings; prints each
model's raw accuracy (fraction of samples within tolerance with no refinement) per condition and the
gap (target: within 10 points), with wall and CPU time.

``--plan``: the user constraint's task (xarm7, tool down at x = 0.4, the `open` scene's query with a box
between start and goal), RRT-Connect with the `project` sampler (or a CVAE trained first on the user
constraint with ``--per-condition`` and ``--epochs``: ``--sampler cvae``); searches interleaved per seed
(seeds 0..runs-1, ``--searches`` picks them): ``python``, the Python search; ``autograd``, the compiled core
calling the user's residual back with the Jacobian by torch autograd (the callback path before central
differences: ``constraint_callbacks.FD_ROWS = 0``); ``callback``, the core calling it back with central
differences of the numpy residual (:func:`manifoldgen.constraint_callbacks.central_difference`; the planner
setting ``compile=False``); ``compiled``, the core running the user's residual traced into a compiled expression
(no Python call per state); ``builtin``, the
same manifold from the built-in orientation + plane constraints (`tool-down-xarm7-builtin.toml`, the plane's
residual compiled too) on the same query; ``builtin-callback``, that with the plane through callbacks (as before
compiled expressions). Prints per search: solved, median CPU and wall time of a query, the median number of
Python constraint calls and configurations per call, the Jacobian calls and their median batch, and the CPU share
inside the user's constraint (or the Python plane's).

``--jacobians``: the callback's Jacobian alone on random xarm7 rows, per batch size: CPU per call of torch
autograd (the constraint's default ``jacobian``) and of central differences, and their largest difference.

``--evaluations``: the core's own cost of one state, what the searches ask for one row at a time: CPU per call of
``residual`` and ``jacobian`` on single random xarm7 rows for the user constraint compiled and through callbacks,
the built-in task (orientation + plane, the plane compiled) and the same manifold from built-in C++ terms only
(orientation + a pose term holding x), and the planner's setup (tracing and checking the user residual).
"""

import argparse
import time
from pathlib import Path

import numpy as np
import torch

from manifoldgen import constraint_callbacks, native
from manifoldgen.data import collect
from manifoldgen.models import get_model_class
from manifoldgen.runtime import set_threads
from manifoldgen.tasks import get_task

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "user_task"
parser = argparse.ArgumentParser()
parser.add_argument("--per-condition", type=int, default=2000)
parser.add_argument("--epochs", type=int, default=60)
parser.add_argument("--samples", type=int, default=4000)
parser.add_argument("--plan", action="store_true", help="time planning: Python search vs compiled core + callbacks")
parser.add_argument("--runs", type=int, default=10)
parser.add_argument("--time", type=float, default=30.0)
parser.add_argument("--sampler", choices=("project", "cvae"), default="project")
SEARCHES = {"python": "Python", "autograd": "core + callbacks, autograd Jacobian",
            "callback": "core + callbacks, central differences", "compiled": "core, compiled user residual",
            "builtin": "core, built-in orientation + plane (plane compiled)",
            "builtin-callback": "core, built-in orientation + plane (plane through callbacks)"}
parser.add_argument("--searches", nargs="+", choices=tuple(SEARCHES), default=list(SEARCHES))
parser.add_argument("--jacobians", action="store_true", help="time the callback's Jacobian: autograd vs central "
                    "differences, per batch size")
parser.add_argument("--evaluations", action="store_true", help="time the core's residual and Jacobian of one "
                    "state: compiled, callbacks, built-in terms")
args = parser.parse_args()
set_threads()
FD_ROWS = constraint_callbacks.FD_ROWS


def count_calls(constraint):
    """Wrap ``constraint``'s residual, jacobian and inequality (instance attributes) to count the Python search's
    calls, rows (configurations) and the CPU seconds spent inside them, and its Jacobian calls and their rows;
    returns the running totals {"calls", "rows", "cpu", "jacobian_calls", "jacobian_rows"}. The task is cached
    (get_task): :func:`uncount` takes the wrappers off again."""
    totals, depth = {"calls": 0, "rows": 0, "cpu": 0.0, "jacobian_calls": 0, "jacobian_rows": 0}, [0]
    for name in ("residual", "jacobian", "inequality"):
        method = getattr(constraint, name)

        def counted(q, y, method=method, name=name):
            outer = not depth[0]  # the autograd Jacobian's own residual call is part of its call
            if outer:
                totals["calls"] += 1
                totals["rows"] += 1 if np.ndim(q) == 1 else len(q)
                if name == "jacobian":
                    totals["jacobian_calls"] += 1
                    totals["jacobian_rows"] += 1 if np.ndim(q) == 1 else len(q)
                began = time.process_time()
            depth[0] += 1
            try:
                return method(q, y)
            finally:
                depth[0] -= 1
                if outer:
                    totals["cpu"] += time.process_time() - began
        setattr(constraint, name, counted)
    return totals


def uncount(constraint) -> None:
    """Take :func:`count_calls`' wrappers off ``constraint`` (its class's methods again)."""
    for name in ("residual", "jacobian", "inequality"):
        constraint.__dict__.pop(name, None)


def plan_bench():
    from dataclasses import replace

    from manifoldgen.planning import RRTConnect, RRTConnectSettings
    from manifoldgen.scene import get_scene
    from manifoldgen.shapes import Obstacle, Pose
    from manifoldgen.space import ConstrainedSpace
    from manifoldgen.specs import make_sampler

    task = get_task(str(EXAMPLES / "tool-down-xarm7.toml"))
    scene = get_scene(task, "open")
    scene = replace(scene, obstacles=[Obstacle("block", "box", Pose([0.4, -0.08, -0.02]), size=[0.2, 0.06, 0.3])])
    sampler = "project"
    if args.sampler == "cvae":
        import tempfile
        folder = Path(tempfile.mkdtemp(prefix="bench-user-cvae-"))
        wall, cpu = time.perf_counter(), time.process_time()
        model = get_model_class("cvae")()
        model.fit(collect(task, args.per_condition, seed=0, progress=False), epochs=args.epochs, seed=0, progress=False,
                  task=task)
        model.save(folder)
        sampler = f"cvae:{folder}"
        print(f"CVAE trained on the user constraint ({args.per_condition} rows per condition, {args.epochs} epochs): "
              f"{time.perf_counter() - wall:.0f} s wall, {time.process_time() - cpu:.0f} s CPU", flush=True)
    rows = {search: [] for search in args.searches}
    for seed in range(args.runs):
        for search in rows:
            builtin = search.startswith("builtin")
            constraint = get_task(str(EXAMPLES / ("tool-down-xarm7-builtin.toml" if builtin else
                                                  "tool-down-xarm7.toml"))).constraint
            space = ConstrainedSpace(constraint, scene.condition, scene.checker(task.robot))
            constraint_callbacks.FD_ROWS = 0 if search == "autograd" else FD_ROWS
            compiled = search in ("compiled", "builtin")
            core = "python" if search == "python" else "native"
            setup = time.process_time()  # the planner with its core (tracing and checking a compiled residual)
            planner = RRTConnect(space, make_sampler(sampler, space, seed), seed=seed,
                                 settings=RRTConnectSettings(core=core, compile=compiled))
            setup = time.process_time() - setup
            totals = count_calls(constraint) if core == "python" else callback_totals
            totals.update(calls=0, rows=0, cpu=0.0, jacobian_calls=0, jacobian_rows=0)
            wall, cpu = time.perf_counter(), time.process_time()
            result = planner.solve(scene.start, scene.goal, args.time)
            cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
            uncount(constraint)
            assert result.extras["core"] == core, result.extras
            if core == "native":  # the core's own count of its calls into Python agrees with ours
                assert result.extras.get("callbacks", {"calls": 0, "rows": 0}) == {"calls": totals["calls"],
                                                                                   "rows": totals["rows"]}
                assert bool(result.extras.get("compiled")) == compiled, result.extras
            if result.solved:
                assert space.validate_path(result.path).valid
            rows[search].append((result.solved, cpu, wall, totals["calls"], totals["rows"], totals["jacobian_calls"],
                                 totals["jacobian_rows"], totals["cpu"] / cpu, setup))
            print(f"seed {seed} {search:>16}: solved {result.solved}, {cpu:.3f} s CPU, {wall:.3f} s wall, "
                  f"setup {setup * 1e3:.1f} ms CPU, "
                  f"{totals['calls']} Python constraint calls, {totals['rows']} configurations, "
                  f"{totals['jacobian_calls']} Jacobian calls ({totals['jacobian_rows']} configurations), "
                  f"{totals['cpu']:.2f} s CPU inside them", flush=True)
    constraint_callbacks.FD_ROWS = FD_ROWS
    print("\n| search | solved | median CPU (s) | median wall (s) | planner setup CPU (ms, median) | Python constraint "
          "calls (median) | configurations per call | Jacobian calls (median) | configurations per Jacobian call "
          "| CPU inside the Python constraint (median) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for search, runs in rows.items():
        solved, cpu, wall, calls, n, jcalls, jn, inside, setup = (np.array(c, float) for c in zip(*runs))
        print(f"| {SEARCHES[search]} | {int(solved.sum())}/{len(runs)} | {np.median(cpu):.3f} | {np.median(wall):.3f} "
              f"| {np.median(setup) * 1e3:.1f} "
              f"| {np.median(calls):,.0f} | {n.sum() / max(calls.sum(), 1):.1f} | {np.median(jcalls):,.0f} "
              f"| {jn.sum() / max(jcalls.sum(), 1):.1f} | {np.median(inside):.0%} |")


def count_callbacks() -> dict:
    """Wrap :class:`manifoldgen.constraint_callbacks.ConstraintCallback`'s ``residuals`` (what the core calls) to count the
    native searches' calls, configurations, Jacobian calls and their configurations, and the CPU inside them;
    returns the running totals (keys as :func:`count_calls`')."""
    totals, residuals = {}, constraint_callbacks.ConstraintCallback.residuals

    def counted(self, q, jacobian):
        totals["calls"] += 1
        totals["rows"] += len(q)
        totals["jacobian_calls"] += int(jacobian)
        totals["jacobian_rows"] += len(q) if jacobian else 0
        began = time.process_time()
        try:
            return residuals(self, q, jacobian)
        finally:
            totals["cpu"] += time.process_time() - began
    constraint_callbacks.ConstraintCallback.residuals = counted
    return totals


def jacobian_bench():
    """CPU per call of the callback's Jacobian on random xarm7 rows: autograd vs central differences."""
    constraint = get_task(str(EXAMPLES / "tool-down-xarm7.toml")).constraint
    robot, rng = constraint.robot, np.random.default_rng(0)

    def per_call(f, reps):
        f()
        began = time.process_time()
        for _ in range(reps):
            f()
        return (time.process_time() - began) / reps

    print("| configurations per call | autograd (ms CPU a call) | central differences (ms CPU a call) | speed-up "
          "| max abs difference |")
    print("|---|---|---|---|---|")
    for B in (1, 4, 16, 32, 64, 128, 256, 512):
        q, y = robot.sample_uniform(B, rng), np.full((B, 1), 0.4)
        reps = max(5, 1000 // B)
        autograd = per_call(lambda: constraint.jacobian(q, y), reps)
        differences = per_call(lambda: constraint_callbacks.central_difference(constraint.residual, q, y), reps)
        error = np.abs(constraint.jacobian(q, y)[1] - constraint_callbacks.central_difference(constraint.residual, q, y)[1]).max()
        print(f"| {B} | {autograd * 1e3:.2f} | {differences * 1e3:.2f} | {autograd / differences:.1f}x | {error:.1e} |")


def evaluation_bench():
    """CPU per call of the core's residual and Jacobian on single xarm7 rows, per way the constraint runs."""
    from manifoldgen.constraints import ConstraintSet, OrientationConstraint, PoseConstraint
    from manifoldgen.space import ConstrainedSpace

    user = get_task(str(EXAMPLES / "tool-down-xarm7.toml")).constraint
    builtin = get_task(str(EXAMPLES / "tool-down-xarm7-builtin.toml")).constraint
    robot = user.robot
    terms = ConstraintSet([OrientationConstraint(robot, "link_eef", direction=(0.0, 0.0, -1.0)),
                           PoseConstraint(robot, "link_eef", np.eye(3), [[0.4]], position_axes=("x",),
                                          orientation_axes=())])
    rows = robot.sample_uniform(2000, np.random.default_rng(0))

    def per_call(f):
        f(rows[:1])
        began = time.process_time()
        for i in range(len(rows)):
            f(rows[i:i + 1])
        return (time.process_time() - began) / len(rows)

    cases = (("user, compiled", user, True), ("user, callbacks", user, False),
             ("built-in task (plane compiled)", builtin, True),
             ("built-in C++ terms only (orientation + pose x)", terms, True))
    times = {label: [] for label, _, _ in cases}
    for _ in range(3):  # rounds, the cases in turn; medians printed
        for label, constraint, compile in cases:
            space = ConstrainedSpace(constraint, [0.4])
            began = time.process_time()
            core = native.core_space(space, compile=compile)
            setup = time.process_time() - began
            times[label].append((per_call(core.residual), per_call(core.jacobian), setup))
    print("| constraint in the core | residual (us CPU a row) | residual + Jacobian (us CPU a row) | core setup "
          "(ms CPU) |")
    print("|---|---|---|---|")
    for label, runs in times.items():
        residual, jacobian, setup = np.median(runs, axis=0)
        print(f"| {label} | {residual * 1e6:.2f} | {jacobian * 1e6:.2f} | {setup * 1e3:.1f} |")


if args.jacobians:
    jacobian_bench()
    raise SystemExit(0)
if args.evaluations:
    evaluation_bench()
    raise SystemExit(0)
if args.plan:
    callback_totals = count_callbacks()
    plan_bench()
    raise SystemExit(0)

rates = {}
for label, file in (("user", "tool-down-xarm7.toml"), ("built-in", "tool-down-xarm7-builtin.toml")):
    task = get_task(str(EXAMPLES / file))
    wall, cpu = time.perf_counter(), time.process_time()
    data = collect(task, args.per_condition, seed=0, progress=False)
    model = get_model_class("cvae")()
    model.fit(data, epochs=args.epochs, seed=0, progress=False, task=task)
    gen = torch.Generator().manual_seed(0)
    rates[label] = {float(y[0]): float(task.constraint.satisfied(model.sample(y, args.samples, gen), y).mean())
                    for y in task.condition.grid}
    print(f"{label:>8}: {len(data)} rows, CVAE {args.epochs} epochs; raw accuracy "
          + ", ".join(f"x={y:g}: {r:.1%}" for y, r in rates[label].items())
          + f"; mean {np.mean(list(rates[label].values())):.1%} "
          f"({time.perf_counter() - wall:.0f} s wall, {time.process_time() - cpu:.0f} s CPU)")
gap = 100 * (np.mean(list(rates["built-in"].values())) - np.mean(list(rates["user"].values())))
print(f"gap (built-in minus user): {gap:+.1f} points (target: within 10)")
