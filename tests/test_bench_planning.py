"""The planning benchmark harness: same seeds for every method, JSONL records, reports, resume."""

import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from manifoldgen.bench.planning import (Experiment, Method, default_baseline, drop_truncated_line, read_records,
                                        run_bench, run_once)
from manifoldgen.bench.report import markdown_table, operations_table, summarize
from manifoldgen.constraints import project
from manifoldgen.errors import ManifoldgenError
from manifoldgen.scene import Scene

METHODS = ["atlas=ompl-atlas-rrtconnect", "pg=rrtconnect@pg"]
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))  # the standalone checkers users run


@pytest.fixture(scope="module")
def easy_scene(tmp_path_factory):
    """No obstacles, a goal 0.4 rad from the panda's home configuration."""
    from manifoldgen.tasks import get_task
    task = get_task("pose", "panda")
    y = task.home_condition
    goal = project(task.constraint, task.home + np.array([0.4, 0.3, 0, 0.3, 0, 0, 0]), y, tol=1e-8).q[0]
    path = tmp_path_factory.mktemp("scene") / "easy.json"
    Scene("easy", [], None, task.home, goal, y, "panda").save(path)
    return str(path)


def test_method_parsing():
    m = Method.parse("cvae=rrtconnect:project@cvae:runs/cvae,refine=2")
    assert (m.label, m.planner, m.local, m.sampler) == ("cvae", "rrtconnect", "project", "cvae:runs/cvae,refine=2")
    m = Method.parse("rrtconnect")
    assert (m.label, m.local, m.sampler) == ("rrtconnect@uniform", "auto", "uniform")
    assert Method.parse("rrtconnect:interpolate").label == "rrtconnect:interpolate@uniform"
    m = Method.parse("ompl-atlas-prm@pg:data/pg.npz")
    assert m.is_ompl and m.label == "ompl-atlas-prm@pg:pg.npz" and m.sampler == "pg:data/pg.npz"
    assert default_baseline(["x=rrtconnect", "ref=ompl-projected-rrtconnect"]) == "ref"
    m = Method.parse("ompl-native-atlas")
    assert m.is_ompl and (m.label, m.local, m.sampler) == ("ompl-native-atlas", "", None)
    for bad, message in [("ompl-curved-rrt", "OMPL methods"), ("rrtconect", "unknown planner"),
                         ("rrtconnect:walk", "unknown local"), ("ompl-atlas-rrt:project", "no local planner"),
                         ("ompl-native-curved", "ompl-native-SPACE"), ("ompl-native-atlas@pg", "without a local")]:
        with pytest.raises(ManifoldgenError, match=message):
            Method.parse(bad)


@pytest.mark.slow
def test_runs_are_recorded_reported_and_resumed(easy_scene, tmp_path):
    out = tmp_path / "bench"
    experiment = Experiment(easy_scene, time_limit=20.0, seed=5)
    table, summaries = run_bench(experiment, METHODS, out, runs=2, workers=2, pg_rows=300, progress=False)
    records = read_records(out / "runs.jsonl")
    assert sorted((r["method"], r["run"], r["seed"]) for r in records) == [
        ("atlas", 0, 5), ("atlas", 1, 6), ("pg", 0, 5), ("pg", 1, 6)]
    for r in records:  # solved means an independently valid path
        assert r["solved"] and r["valid"] and r["planner_solved"] and r["why"].startswith("solved in")
        assert r["worst_violation"] <= 1.0 and r["time_s"] < r["time_limit"] and not r["late"]
        assert 0 < r["cpu_s"]
        ops = r["ops"]  # counted at the source: every solve evaluates, checks and grows trees
        assert ops["fk"] > 0
        if r["method"] == "pg":  # ours: the sphere broad phase by default, which spares coal in this open scene
            assert r["extras"]["sphere_checks"] > 0
        else:
            assert ops["collision_checks"] > 0
        if r["method"] == "atlas":  # OMPL: a Newton step is one Jacobian; nodes are its planner's vertices
            assert ops["jacobians"] == ops["projection_steps"] > 0 and ops["nodes"] == r["iterations"] >= 2
        assert ops["samples"] == r["samples_drawn"]
        if r["method"] == "pg":  # the sampler's rows: made, then some of them checked as samples
            made = r["extras"]["sampler"]
            assert made["accepted"] <= made["checked"] <= made["generated"]
    # the same seed gives the same run (OMPL reseeded in every worker, our samplers seeded)
    rerun = run_once(experiment, Method.parse(METHODS[0]), 1)
    first = next(r for r in records if (r["method"], r["run"]) == ("atlas", 1))
    assert (rerun["length"], rerun["iterations"]) == (first["length"], first["iterations"])
    assert [(s.method, s.runs, s.solved) for s in summaries] == [("atlas", 2, 2), ("pg", 2, 2)]
    text = (out / "results.md").read_text()
    assert "| atlas | 2 | 100.0 |" in text and "| pg | 2 | 100.0 |" in text and table in text
    assert "| Median CPU (s) |" in text and "| atlas | 2/2 |" in text and "| pg | 2/2 |" in text
    assert "| Sampler rows made | Sampler rows checked |" in text
    assert "- `atlas`: OMPL through its Python bindings (atlas) (2 runs)" in text  # where each method ran
    assert "- `pg`: compiled core (2 runs)" in text or "- `pg`: Python search" in text
    assert (out / "time.png").read_bytes()[:4] == b"\x89PNG" and (out / "length.png").stat().st_size > 0
    assert json.loads((out / "config.json").read_text())["methods"] == METHODS
    assert (out / "pg-easy-300.npz").is_file()
    # every run's path, OMPL's included, rechecked outside the project from the folder alone (pinocchio + coal)
    from check_path import bench_checks
    reports = list(bench_checks(out, None, None, None))
    assert [r["status"] for r in reports] == [0] * 5, [r["line"] for r in reports]
    assert reports[-1]["line"].endswith("4 solved runs rechecked above, 0 unsolved (no path)")

    with pytest.raises(ManifoldgenError, match="--resume"):
        run_bench(experiment, METHODS, out, runs=2, progress=False)
    # resume: nothing left for 2 runs; one more run per method for 3
    run_bench(experiment, METHODS, out, runs=2, resume=True, pg_rows=300, progress=False)
    assert len(read_records(out / "runs.jsonl")) == 4
    _, summaries = run_bench(experiment, METHODS, out, runs=3, resume=True, pg_rows=300, progress=False)
    records = read_records(out / "runs.jsonl")
    assert len(records) == 6 and sorted(r["run"] for r in records if r["method"] == "pg") == [0, 1, 2]
    assert [s.runs for s in summaries] == [3, 3]
    with pytest.raises(ManifoldgenError, match="same scene, time limit"):
        run_bench(Experiment(easy_scene, time_limit=5.0, seed=5), METHODS, out, runs=3, resume=True,
                  progress=False)


def test_summary_counts_failures_at_the_limit():
    records = [{"method": "a", "solved": True, "time_s": 1.0, "cpu_s": 0.8, "time_limit": 10.0, "length": 2.0,
                "samples_drawn": 5, "projections": 0, "worst_violation": 0.5},
               {"method": "a", "solved": False, "time_s": 3.0, "time_limit": 10.0, "length": 0.0,
                "samples_drawn": 9, "projections": 0, "worst_violation": float("nan"), "error": "x"}]
    (s,) = summarize(records)
    assert (s.runs, s.solved, s.errors, s.success) == (2, 1, 1, 50.0)
    assert (s.time_mean, s.time_min, s.time_max, s.time_median) == (5.5, 1.0, 10.0, 5.5)
    assert (s.cpu_median, s.length_mean, s.samples_mean, s.worst_violation) == (0.8, 2.0, 5.0, 0.5)
    fast = [{**r, "method": "b", "time_s": 0.5, "solved": True} for r in records]
    table = markdown_table(summarize(records + fast), baseline="a")
    assert "| b | 2 | 100.0 |" in table and "≥11.0x |" in table  # a's median run failed: a lower bound
    late = [{**records[1], "time_s": 14.0}]  # answered 4 s after its limit: counted at what it really ran
    assert summarize(late)[0].time_max == 14.0
    none = markdown_table(summarize(late + fast), baseline="a")
    assert "speed-up" not in none.splitlines()[0] and "the baseline a solved none of its runs" in none


def test_the_operations_table_gives_the_cores_collision_queries():
    """With sphere models the core's collision queries are its sphere tests plus its certified sweep tests: their
    median over the solved runs; '-' for a method without them, and a failed run does not count."""
    ops = {"fk": 10, "jacobians": 1, "projection_steps": 1, "collision_checks": 4, "samples": 2, "nodes": 3}
    run = {"method": "core", "solved": True, "cpu_s": 0.1, "time_s": 0.1, "ops": ops}
    records = [{**run, "extras": {"sphere_checks": 100, "sweep_checks": 20}},
               {**run, "extras": {"sphere_checks": 300, "sweep_checks": 40}},
               {**run, "solved": False, "extras": {"sphere_checks": 9000, "sweep_checks": 0}},
               {**run, "method": "plain", "extras": {}}]
    table = operations_table(records, ["core", "plain"]).splitlines()
    column = table[0].split(" | ").index("Collision queries (sphere + sweep tests)")
    assert table[2].split(" | ")[column] == "230" and table[3].split(" | ")[column] == "-"


RECORD = {"method": "a", "spec": "a=rrtconnect@project", "run": 0, "seed": 0, "scene": "wall", "time_limit": 1.0,
          "solved": False, "planner_solved": False, "valid": False, "time_s": 1.0, "length": 0.0, "iterations": 3,
          "samples_drawn": 10, "projections": 0, "waypoints": 0, "cpu_s": 0.9}


def test_truncated_last_line_is_ignored(tmp_path):
    path = tmp_path / "runs.jsonl"
    line = json.dumps(RECORD)
    path.write_text(line + '\n{"method": "a", "ru')
    assert read_records(path) == [RECORD]
    drop_truncated_line(path)
    assert path.read_text() == line + "\n"
    path.write_text('{"method": "a", "ru\n' + line + "\n")
    with pytest.raises(ManifoldgenError, match="line 1"):
        read_records(path)


@pytest.mark.parametrize("change, problem", [
    ({"solved": "yes"}, "solved is 'yes'"), ({"cpu_s": -5}, "cpu_s is -5"), ({"time_s": float("nan")}, "time_s is nan"),
    ({"run": True}, "run is True"), ({"method": None}, "method is None"), ({"solved": True, "valid": True},
                                                                          "a solved run without its path")])
def test_a_tampered_record_is_refused_on_reading(tmp_path, change, problem):
    path = tmp_path / "runs.jsonl"
    path.write_text(json.dumps(RECORD) + "\n" + json.dumps({**RECORD, "run": 1, **change}) + "\n")
    with pytest.raises(ManifoldgenError, match=f"line 2 is not a run record as bench writes it \\({re.escape(problem)}"):
        read_records(path)
    path.write_text(json.dumps(RECORD) + "\n" + json.dumps(RECORD) + "\n")
    with pytest.raises(ManifoldgenError, match="a second record of run 0 of 'a'"):
        read_records(path)
