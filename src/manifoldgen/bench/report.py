"""Planning benchmark reports: per-method summaries, Markdown tables and box plots.

Input is the list of run records a benchmark wrote (one JSON object per run, see
:mod:`manifoldgen.bench.planning`). An unsolved run counts as a failure whose time is the
run's time limit, as in the paper's tables, or the time it really ran when that was longer.
"""

from __future__ import annotations

import io
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from manifoldgen.io import PNG_METADATA, atomic_write_bytes, atomic_write_text
from manifoldgen.planning.result import engine
from manifoldgen.space import ValidationSettings


@dataclass
class MethodSummary:
    """One method's runs: success rate (%), times (s, failures at the limit or longer), means over solved runs."""

    method: str
    runs: int
    solved: int
    errors: int
    success: float
    time_mean: float
    time_min: float
    time_max: float
    time_median: float
    cpu_median: float
    length_mean: float
    samples_mean: float
    projections_mean: float
    worst_violation: float

    def to_dict(self) -> dict:
        return asdict(self)


def run_time(record: dict) -> float:
    """The time a run counts for: its solve time when solved, else its time limit or, when it ran longer (a
    search answering late), the time it ran."""
    return float(record["time_s"]) if record["solved"] else max(float(record["time_s"]), float(record["time_limit"]))


def summarize(records: list[dict], methods: list[str] | None = None) -> list[MethodSummary]:
    """Summaries in the order of ``methods`` (default: first appearance in ``records``)."""
    order = methods if methods is not None else list(dict.fromkeys(r["method"] for r in records))
    out = []
    for method in order:
        runs = [r for r in records if r["method"] == method]
        if not runs:
            continue
        solved = [r for r in runs if r["solved"]]
        times = np.array([run_time(r) for r in runs])
        mean = (lambda key: float(np.mean([r[key] for r in solved])) if solved else float("nan"))
        worst = max((float(r["worst_violation"]) for r in solved), default=float("nan"))
        cpu = [float(r["cpu_s"]) for r in solved if "cpu_s" in r]
        out.append(MethodSummary(method, len(runs), len(solved), sum(bool(r.get("error")) for r in runs),
                                 100.0 * len(solved) / len(runs), float(times.mean()), float(times.min()),
                                 float(times.max()), float(np.median(times)),
                                 float(np.median(cpu)) if cpu else float("nan"), mean("length"),
                                 mean("samples_drawn"), mean("projections"), worst))
    return out


def _num(value: float, digits: int = 3) -> str:
    return "-" if not np.isfinite(value) else f"{value:.{digits}g}" if abs(value) < 1e4 else f"{value:,.0f}"


def markdown_table(summaries: list[MethodSummary], baseline: str | None = None) -> str:
    """The paper's table (average / min / max time, success) plus median wall time, median CPU time of
    the solved runs (the planner process's own CPU, insensitive to other load), path length, samples,
    projections and the worst constraint violation (x tolerance) along solved paths; with
    ``baseline`` a column of median speed-ups over that method (marked as lower bounds, >=, when
    the baseline's median run failed and so counts at the time limit; none, said below the table, when it
    solved no run)."""
    base = next((s for s in summaries if s.method == baseline), None)
    if base is not None and not base.solved:  # a ratio to a method that solved nothing measures nothing
        return markdown_table(summaries) + f"\nNo speed-up column: the baseline {baseline} solved none of its runs.\n"
    reference = None if base is None else base.time_median
    bound = "≥" if base is not None and base.success <= 50 else ""  # its median run failed: a lower bound
    header = ["Method", "Runs", "Success (%)", "Mean time (s)", "Min (s)", "Max (s)", "Median (s)",
              "Median CPU, solved (s)", "Path length (rad)", "Samples drawn", "Projections", "Worst violation (x tol)"]
    if reference is not None:
        header.append(f"Median speed-up vs {baseline}")
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for s in summaries:
        row = [s.method, str(s.runs), f"{s.success:.1f}", _num(s.time_mean), _num(s.time_min), _num(s.time_max),
               _num(s.time_median), _num(s.cpu_median), _num(s.length_mean), _num(s.samples_mean),
               _num(s.projections_mean), _num(s.worst_violation)]
        if reference is not None:
            row.append(f"{bound}{reference / s.time_median:.1f}x" if s.time_median > 0 else "-")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


OPERATIONS = ("fk", "jacobians", "projection_steps", "collision_checks", "samples", "nodes")


def operations_table(records: list[dict], methods: list[str]) -> str:
    """Markdown: per method, medians over its solved runs of the CPU time, the wall time, each operation count
    of the records' ``ops`` (see :func:`manifoldgen.bench.planning.operations`), the collision queries of the
    compiled core with sphere models (its sphere tests plus its certified sweep tests, ``extras``; '-' without
    sphere models) and the sampler's rows made (decoded, for a model) and checked as samples
    (``extras['sampler']``; a search keeps some of them as nodes)."""
    header = ["Method", "Solved", "Median CPU (s)", "Median wall (s)", "FK", "Jacobians", "Projection steps",
              "Collision checks", "Samples", "Nodes", "Collision queries (sphere + sweep tests)", "Sampler rows made",
              "Sampler rows checked"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for method in methods:
        runs = [r for r in records if r["method"] == method]
        solved = [r for r in runs if r["solved"] and "ops" in r]
        median = (lambda values: _num(float(np.median(values))) if values else "-")
        stats = [r["extras"]["sampler"] for r in solved if "sampler" in r.get("extras", {})]  # none: OMPL's own
        queries = [r["extras"]["sphere_checks"] + r["extras"].get("sweep_checks", 0) for r in solved
                   if r.get("extras", {}).get("sphere_checks")]
        row = [method, f"{len(solved)}/{len(runs)}", median([r["cpu_s"] for r in solved]),
               median([r["time_s"] for r in solved])] + [median([r["ops"][k] for r in solved]) for k in OPERATIONS] \
            + [median(queries)] + [median([counts[k] for counts in stats if k in counts]) for k in ("generated",
                                                                                                 "checked")]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def stability_table(records: list[dict], methods: list[str]) -> str:
    """Markdown: per method, the static stability of its solved paths (balance tasks; '' when no record has it):
    mean and worst share of states whose CoM leaves the support polygon, paths with any such state, the
    smallest CoM depth inside the polygon (m, negative: outside), the mean share of states with a foot off
    its fixed spot by more than the tolerance, and the largest foot drift (m); with ``bench plan --physics``,
    the paths that stayed upright in MuJoCo and their largest base tilt (degrees) and foot slip (m)."""
    rows = []
    physics = any(r.get("physics") for r in records)
    for method in methods:
        found = [r["stability"] for r in records if r["method"] == method and r["solved"] and r.get("stability")]
        if not found:
            continue
        unstable = [s["unstable_fraction"] for s in found]
        rows.append([method, str(len(found)), f"{100 * np.mean(unstable):.1f}", f"{100 * np.max(unstable):.1f}",
                     f"{sum(u > 0 for u in unstable)} / {len(found)}", f"{min(s['min_depth'] for s in found):.3f}",
                     f"{100 * np.mean([s['feet_moved_fraction'] for s in found]):.1f}",
                     f"{max(s['max_foot_drift'] for s in found):.3f}"])
        if physics:
            ran = [r["physics"] for r in records if r["method"] == method and r["solved"] and r.get("physics")]
            rows[-1] += ([f"{sum(p['upright'] for p in ran)} / {len(ran)}", f"{max(p['max_tilt_deg'] for p in ran):.2f}",
                          f"{max(p['max_slip_m'] for p in ran):.3f}"] if ran else ["-", "-", "-"])
    if not rows:
        return ""
    header = ["Method", "Solved paths", "CoM outside polygon, mean (% of states)", "worst path (%)",
              "Paths with an unstable state", "Min CoM depth (m)", "Feet off their spots, mean (% of states)",
              "Max foot drift (m)"] + (["Upright in MuJoCo", "Max tilt (deg)", "Max foot slip (m)"] if physics else [])
    return "\n".join(["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
                     + ["| " + " | ".join(r) + " |" for r in rows]) + "\n"


def box_plot(records: list[dict], key: str, methods: list[str], title: str, ylabel: str, *,
             solved_only: bool = False, log: bool = True) -> bytes:
    """PNG bytes: one box per method of ``key`` (``time`` counts failures at the limit)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    values, labels = [], []
    for method in methods:
        runs = [r for r in records if r["method"] == method and (r["solved"] or not solved_only)]
        data = [run_time(r) if key == "time" else float(r[key]) for r in runs]
        if data:
            values.append(data)
            labels.append(method)
    fig, ax = plt.subplots(figsize=(max(5.0, 1.1 * len(labels) + 2), 4.5))
    if values:
        ax.boxplot(values)
        ax.set_xticks(range(1, len(labels) + 1), labels, rotation=30, ha="right")
    if log and values and min(min(v) for v in values) > 0:
        ax.set_yscale("log")
    ax.set_title(title)
    ax.set_ylabel(ylabel)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=120, metadata=PNG_METADATA)
    plt.close(fig)
    return buffer.getvalue()


def _stability_section(records: list[dict], methods: list[str]) -> str:
    table = stability_table(records, methods)
    return ("\nStatic stability along the solved paths (every state every "
            f"{ValidationSettings.resolution} rad):\n\n" + table) if table else ""


def engine_lines(records: list[dict], order: list[str]) -> str:
    """Where each method's searches ran (and why not in the compiled core), with its run count: a Markdown list."""
    lines = []
    for method in order:
        counts: dict[str, int] = {}
        for r in records:
            if r["method"] == method:
                where = engine(r.get("extras", {}))
                counts[where] = counts.get(where, 0) + 1
        lines.append(f"- `{method}`: " + "; ".join(f"{where} ({n} runs)" for where, n in counts.items()))
    return "\nWhere each method's searches ran:\n\n" + "\n".join(lines) + "\n"


def write_report(records: list[dict], out_dir: str | Path, title: str, *, methods: list[str] | None = None,
                 baseline: str | None = None, notes: str = "") -> tuple[str, list[MethodSummary]]:
    """Write ``results.md``, ``time.png`` and ``length.png`` to ``out_dir``; return the table and summaries."""
    out_dir = Path(out_dir)
    summaries = summarize(records, methods)
    order = [s.method for s in summaries]
    table = markdown_table(summaries, baseline)
    limits = sorted({float(r["time_limit"]) for r in records})
    text = (f"# {title}\n\n{notes}\n\nTime limit per run: {', '.join(f'{t:g}' for t in limits)} s; an unsolved "
            "run counts as a failure with time = limit. Path length, samples and projections are means over "
            "solved runs: samples are configurations taken from our samplers (OMPL's internal sampling is not "
            "counted), projections are configurations projected onto the manifold (OMPL: calls of its "
            "Constraint::project; Atlas and TangentBundle project through charts and count 0). The worst "
            "violation is max |F_i| / tol_i over every state of every solved path, checked every "
            f"{ValidationSettings.resolution} rad."
            "\n\n" + table + engine_lines(records, order) + _stability_section(records, order)
            + "\nWhat the solved runs cost (medians over solved runs; CPU: the planner process's own; the C++ "
            "baseline's: its program's plus our dense check of its paths, not the harness around it; FK: "
            "configurations whose constraint kinematics was computed, Jacobians included; collision checks: "
            "configurations checked, robot-robot and robot-scene pairs together, each with its own FK of every link; "
            "collision queries: with sphere models, the compiled core's sphere tests plus its certified sweep tests; "
            "samples: from our samplers, or drawn by the C++ OMPL baseline's sampler, not counted for the "
            "Python-callback OMPL methods):\n\n"
            + operations_table(records, order) + "\n![time](time.png)\n\n![length](length.png)\n")
    atomic_write_text(out_dir / "results.md", text)
    atomic_write_bytes(out_dir / "time.png", box_plot(records, "time", order, f"{title}: planning time",
                                                      "time (s, failures at the limit)"))
    atomic_write_bytes(out_dir / "length.png", box_plot(records, "length", order, f"{title}: path length",
                                                        "joint-space length (rad)", solved_only=True, log=False))
    return table, summaries
