"""Table I and beyond: sampling time, accuracy and coverage of trained models.

``run_sampling_bench(model_dirs, out)`` times ``model.sample`` for 100 ... 100k rows (warm,
median of repeats), measures the raw and refined within-tolerance rates and the k-NN
precision/recall/density/coverage and MMD against a dense reference set (fresh projection
samples) at training conditions and at unseen ones between and beyond them (for k > 1 conditions,
such as the dual-arm tray's (d, pitch): a few training values and midpoints along each axis), and writes
``results.json``, ``table.md``, ``fig2_samples.png`` (paper Fig. 2), ``residuals.png`` and
``coverage.png`` into ``out``.
"""

from __future__ import annotations

import json
import warnings
import time
from pathlib import Path

import numpy as np
import torch

from manifoldgen.data import collect
from manifoldgen.errors import ManifoldgenError, short
from manifoldgen.io import atomic_write_text, check_own_folder, locks_output
from manifoldgen.metrics import accuracy, coverage_metrics
from manifoldgen.models import ConditionalSampler, load_model
from manifoldgen.progress import progress_bar
from manifoldgen.provenance import check_model_for
from manifoldgen.runtime import check_seed, set_threads
from manifoldgen.tasks import Task, task_from_meta

COUNTS = (100, 1_000, 10_000, 100_000)
MIN_ROWS = 20  # samples and reference rows per condition: the k-NN metrics need more than k (5) of each
RESULTS_FILE = "results.json"  # written first: a folder holding it is a sampling benchmark's
OUTPUT_FILES = (RESULTS_FILE, "table.md", "fig2_samples.png", "residuals.png", "coverage.png")


def time_sampling(model: ConditionalSampler, y: np.ndarray, counts: tuple[int, ...] = COUNTS, repeats: int = 7,
                  seed: int = 0, threads: int = 2) -> dict[int, float]:
    """Median wall time (ms) of ``model.sample(y, n)`` per n on ``threads`` torch threads, after a warm-up.

    The thread count is set here because pinocchio's parallel collision checks reset OpenMP's.
    """
    set_threads(threads)
    generator = torch.Generator().manual_seed(seed)
    result = {}
    for n in counts:
        model.sample(y, n, generator)
        times = []
        for _ in range(repeats):
            tic = time.perf_counter()
            model.sample(y, n, generator)
            times.append(time.perf_counter() - tic)
        result[n] = 1e3 * float(np.median(times))
    return result


def default_conditions(values: np.ndarray) -> tuple[list[float], list[float]]:
    """Seen conditions (the training values) and unseen ones: midpoints between the first
    three and the last pair, and one step beyond the top (panda: 0.25, 0.45, 0.65, 0.75)."""
    v = np.unique(np.asarray(values, float).ravel())
    step = float(np.min(np.diff(v))) if len(v) > 1 else 0.1
    mids = (v[:-1] + v[1:]) / 2
    picks = sorted({float(mids[0]), float(mids[len(mids) // 2]), float(mids[-1])})
    return [float(x) for x in v], [round(x, 6) for x in picks] + [round(float(v[-1] + step / 2), 6)]


def default_grid_conditions(grid: np.ndarray, count: int = 4) -> tuple[list[tuple], list[tuple]]:
    """For a (V, k) training grid with k > 1: seen = ``count`` training values along the grid's diagonal (each
    axis's values from first to last); unseen = for each axis, the midpoint of its two central values with the
    others at a central training value, and one point midway on every axis."""
    grid = np.asarray(grid, float)
    axes = [np.unique(grid[:, i]) for i in range(grid.shape[1])]
    picks = [[v[int(round(j))] for j in np.linspace(0, len(v) - 1, count)] for v in axes]
    seen = list(dict.fromkeys(tuple(float(p[c]) for p in picks) for c in range(count)))
    centre = [v[(len(v) - 1) // 2] for v in axes]
    mids = [(v[(len(v) - 1) // 2] + v[min(len(v) - 1, (len(v) + 1) // 2)]) / 2 for v in axes]
    unseen = [tuple(round(float(mids[i] if j == i else centre[j]), 6) for j in range(len(axes)))
              for i in range(len(axes))]
    return seen, unseen + [tuple(round(float(m), 6) for m in mids)]


def _trained_values(meta: dict) -> list[list[float]]:
    """The condition values a model's data was collected at (the keys of its meta's ``coverage.modes``, as
    :func:`manifoldgen.data.collect` records them; none where it recorded none)."""
    modes = meta.get("coverage", {}).get("modes", {})
    return [json.loads(key) for key in modes]


def _rows(values, k: int) -> list[tuple]:
    """Conditions as k-tuples (a bare number is one value of a k = 1 condition)."""
    out = []
    for v in values:
        row = tuple(float(x) for x in np.ravel(v))
        if len(row) != k:
            raise ManifoldgenError(f"condition {list(row)} has {len(row)} value(s); the task has {k}: give "
                                   f"{k} comma-separated values")
        if not np.isfinite(row).all():
            raise ManifoldgenError(f"condition {list(row)} must be finite numbers; give values inside the task's range")
        out.append(row)
    return out


def _key(y: tuple) -> str:
    """One condition's name in results and tables: ``0.3`` (k = 1) or ``0.3,0`` (k > 1)."""
    return str(y[0]) if len(y) == 1 else ",".join(f"{v:g}" for v in y)


def _plain(ys: list[tuple]) -> list:
    return [y[0] if len(y) == 1 else list(y) for y in ys]


@locks_output("out")  # one benchmark per output folder
def run_sampling_bench(model_dirs: list[str | Path], out: str | Path, *, samples: int = 3000, refine: int = 3,
                       reference_rows: int = 3000, repeats: int = 7, counts: tuple[int, ...] = COUNTS,
                       seen: list[float] | None = None, unseen: list[float] | None = None, seed: int = 0,
                       threads: int = 2, progress: bool = True, task: Task | None = None,
                       trust_code: bool = False) -> dict:
    """Benchmark every model in ``model_dirs`` on its task (``task``, ``trust_code``: see
    :func:`~manifoldgen.tasks.task_from_meta`); write the report into ``out``."""
    if not model_dirs:
        raise ManifoldgenError("give at least one model directory to benchmark")
    limits = {"--samples": (samples, MIN_ROWS, 10**6), "--reference": (reference_rows, MIN_ROWS, 10**6),
              "--repeats": (repeats, 1, 1000), "--refine": (refine, 0, 1000), "--threads": (threads, 1, 256)}
    for option, (value, low, high) in limits.items():
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise ManifoldgenError(f"{option} must be an integer from {low} to {high:,}, got {value!r}")
    seed = check_seed(seed)
    if len({Path(d).resolve() for d in model_dirs}) < len(model_dirs):
        raise ManifoldgenError(f"a model directory is given twice in {[str(d) for d in model_dirs]}; give each once")
    out = Path(out)
    check_own_folder(out, (RESULTS_FILE,))
    models = {str(d): load_model(d) for d in model_dirs}
    first = next(iter(models.values()))
    task = task_from_meta(first.meta, task=task, trust_code=trust_code, what=f"model {next(iter(models))}")
    for path, model in models.items():
        check_model_for(model, task.constraint, f"model {path}")
    k = task.condition.k
    if k == 0:
        raise ManifoldgenError("the sampling benchmark needs a conditioned task (its condition has no values)")
    default_seen, default_unseen = (default_conditions(task.condition.values) if k == 1
                                    else default_grid_conditions(task.condition.grid))
    trained = {path: {tuple(np.round(row, 9)) for row in _trained_values(model.meta)} for path, model in models.items()}
    if seen:  # the user's: each a condition every model (that records its own) was trained at
        never = next(((y, path) for y in _rows(seen, k) for path, values in trained.items()
                      if values and tuple(np.round(y, 9)) not in values), None)
        if never is not None:
            raise ManifoldgenError(f"--seen {list(never[0])} is not a condition model {never[1]} was trained at (it "
                                   f"was at {short(_plain(sorted(trained[never[1]])), 60)}); give training values "
                                   "(or list it under --unseen)")
    seen, unseen = _rows(seen or default_seen, k), _rows(unseen or default_unseen, k)
    known = next((y for y in unseen if any(tuple(np.round(y, 9)) in values for values in trained.values())), None)
    if known is not None:
        raise ManifoldgenError(f"--unseen {list(known)} is a condition a model was trained at; give conditions between "
                               "or beyond the training ones (or list it under --seen)")
    out.mkdir(parents=True, exist_ok=True)
    conditions = [*seen, *unseen]
    check_seed(seed + 1000 + len(conditions), "--seed (+ 1000 + i seeds the reference set of condition i)")
    robot, constraint = task.robot, task.constraint

    reference = {}
    with progress_bar("reference sets", total=len(conditions), enabled=progress) as bar:
        for i, y in enumerate(conditions):
            try:
                reference[y] = collect(task, reference_rows, seed + 1000 + i, conditions=[y], progress=False).q
            except ManifoldgenError as exc:  # a condition the robot cannot reach is reported and skipped
                warnings.warn(f"condition {_key(y)} skipped: {exc}")
            bar.advance(1)
    seen, unseen = [y for y in seen if y in reference], [y for y in unseen if y in reference]
    conditions = [*seen, *unseen]
    if not seen:
        raise ManifoldgenError("no seen condition is reachable; give --seen values inside the task's range "
                               f"({task.condition.describe()})")

    results: dict = {"task": task.name, "robot": robot.name, "samples": samples, "refine": refine,
                     "reference_rows": reference_rows, "seen": _plain(seen), "unseen": _plain(unseen),
                     "threads": threads, "models": {}}
    valid_rows: dict[str, np.ndarray] = {}
    violations: dict[str, np.ndarray] = {}
    with progress_bar("models", total=len(models) * (len(conditions) + 1), enabled=progress) as bar:
        for label, model in models.items():
            name = _label(model, label, models)
            entry = {"dir": label, "model": model.label, "per_condition": {}}
            entry["time_ms"] = {str(n): t for n, t in
                                time_sampling(model, np.array(seen[len(seen) // 2]), counts, repeats, seed,
                                              threads).items()}
            bar.advance(1)
            generator = torch.Generator().manual_seed(seed)
            valid, viol = [], []
            for y in conditions:
                ys = np.tile(np.asarray(y), (samples, 1))
                q = model.sample(list(y), samples, generator)
                acc, _ = accuracy(constraint, q, ys, refine)
                cov = coverage_metrics(reference[y], q, robot.lower, robot.upper)
                entry["per_condition"][_key(y)] = {**acc.to_dict(), **cov, "seen": y in seen}
                if y in seen:
                    ok = constraint.satisfied(q, ys)
                    valid.append(q[ok])
                    viol.append(acc.residual)
                bar.advance(1)
            entry["seen"] = _average(entry["per_condition"], seen)
            entry["unseen"] = _average(entry["per_condition"], unseen)
            results["models"][name] = entry
            valid_rows[name] = np.concatenate(valid)
            violations[name] = np.concatenate(viol)

    atomic_write_text(out / RESULTS_FILE, json.dumps(results, indent=1))
    atomic_write_text(out / "table.md", markdown_table(results))
    from manifoldgen.viz.samples import plot_coverage, plot_end_effector, plot_residuals
    frame = task.constraint.spec().get("frame")
    if frame is not None:
        plot_end_effector({k: robot.frame_pose(v, frame)[0] for k, v in valid_rows.items()},
                          out / "fig2_samples.png", title=f"{robot.name} {task.name}: end-effector positions "
                                                         "of valid raw samples (training heights)")
    plot_residuals(violations, out / "residuals.png")
    plot_coverage(results, out / "coverage.png")
    return results


def _label(model: ConditionalSampler, label: str, models: dict) -> str:
    """The model's name; with others of its kind, its folder name too (its whole path when names collide)."""
    same = [k for k, m in models.items() if m.label == model.label]
    if len(same) == 1:
        return model.label
    names = [Path(k).name for k in same]
    return f"{model.label} ({Path(label).name if names.count(Path(label).name) == 1 else label})"


def _average(per_condition: dict, ys: list[tuple]) -> dict:
    keys = ("raw", "refined", "precision", "recall", "density", "coverage", "mmd")
    rows = [per_condition[_key(y)] for y in ys]
    return {k: float(np.mean([r[k] for r in rows])) if rows else float("nan") for k in keys}


def markdown_table(results: dict) -> str:
    """Table I (sampling time) and the accuracy/coverage table, as Markdown."""
    names = list(results["models"])
    counts = list(next(iter(results["models"].values()))["time_ms"])
    lines = [f"## Sampling time (ms, median of warm repeats, {results['threads']} CPU threads)", "",
             "| samples | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
    for n in counts:
        lines.append(f"| {int(n):,} | " + " | ".join(f"{results['models'][m]['time_ms'][n]:.1f}" for m in names)
                     + " |")
    lines += ["", f"## Accuracy and coverage ({results['samples']} samples per condition, "
              f"refine = {results['refine']} LM iterations, reference {results['reference_rows']} projection "
              "samples per condition)", "",
              "| model | conditions | raw valid | valid after refine | precision | recall | density | coverage | MMD |",
              "|---|---|---|---|---|---|---|---|---|"]
    for m in names:
        for part, ys in (("seen", results["seen"]), ("unseen", results["unseen"])):
            if not ys:
                continue
            a = results["models"][m][part]
            named = ", ".join(f"{y:g}" if np.ndim(y) == 0 else "(" + ", ".join(f"{v:g}" for v in y) + ")" for y in ys)
            lines.append(f"| {m} | {part} {named} | {a['raw']:.1%} | {a['refined']:.2%} | "
                         f"{a['precision']:.3f} | {a['recall']:.3f} | {a['density']:.3f} | {a['coverage']:.3f} | "
                         f"{a['mmd']:.4f} |")
    lines += ["", "## Per condition", "", "| model | y | raw valid | refined | recall | coverage |",
              "|---|---|---|---|---|---|"]
    for m in names:
        for y, r in results["models"][m]["per_condition"].items():
            lines.append(f"| {m} | {y}{'' if r['seen'] else ' (unseen)'} | {r['raw']:.1%} | {r['refined']:.2%} | "
                         f"{r['recall']:.3f} | {r['coverage']:.3f} |")
    return "\n".join(lines) + "\n"
