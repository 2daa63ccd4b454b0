"""Metrics on distributions with known answers, and the sampling benchmark end to end."""

from __future__ import annotations

import json

import numpy as np
import pytest

from manifoldgen.metrics import accuracy, coverage_metrics, mmd, prdc
from manifoldgen.bench.sampling import default_conditions, run_sampling_bench
from manifoldgen.data import collect
from manifoldgen.models import CGAN, CVAE


@pytest.fixture
def cloud():
    return np.random.default_rng(0).normal(size=(600, 3))


def test_identical_sets_score_perfectly(cloud):
    m = prdc(cloud, cloud, k=5)
    assert m.precision == 1.0 and m.recall == 1.0 and m.coverage == 1.0
    assert m.density >= 1.0
    assert abs(mmd(cloud, cloud)) < 0.01


def test_same_distribution_scores_high(cloud):
    other = np.random.default_rng(1).normal(size=(600, 3))
    m = prdc(cloud, other, k=5)
    assert min(m.precision, m.recall, m.coverage) > 0.85
    assert abs(mmd(cloud, other)) < 0.01


def test_disjoint_sets_score_zero(cloud):
    m = prdc(cloud, cloud + 100.0, k=5)
    assert m.precision == m.recall == m.density == m.coverage == 0.0
    assert mmd(cloud, cloud + 100.0) > 1.0


def test_collapsed_set_has_high_precision_low_recall(cloud):
    collapsed = np.random.default_rng(2).normal(scale=0.05, size=(600, 3))
    m = prdc(cloud, collapsed, k=5)
    assert m.precision > 0.9
    assert m.recall < 0.2 and m.coverage < 0.2
    assert mmd(cloud, collapsed) > 0.05


def test_accuracy_of_manifold_rows_and_noise(panda_task):
    data = collect(panda_task, 50, seed=2, conditions=[[0.4]], progress=False)
    acc, refined = accuracy(panda_task.constraint, data.q, data.y, refine=3)
    assert acc.raw == 1.0 and acc.refined == 1.0 and np.all(acc.residual <= 1.0)
    noisy = data.q + np.random.default_rng(0).normal(0, 0.05, data.q.shape)
    acc, refined = accuracy(panda_task.constraint, noisy, data.y, refine=3)
    assert acc.raw < 0.2 and acc.refined > 0.9
    assert panda_task.constraint.satisfied(refined, data.y).mean() == acc.refined
    cov = coverage_metrics(data.q, data.q, panda_task.robot.lower, panda_task.robot.upper, k=3)
    assert cov["recall"] == 1.0


def test_default_conditions_between_and_beyond():
    seen, unseen = default_conditions(np.array([[0.2], [0.3], [0.4], [0.5], [0.6], [0.7]]))
    assert seen == pytest.approx([0.2, 0.3, 0.4, 0.5, 0.6, 0.7])
    assert unseen == pytest.approx([0.25, 0.45, 0.65, 0.75])


@pytest.mark.slow
def test_sampling_bench_writes_report(panda_task, tmp_path):
    data = collect(panda_task, 80, seed=6, conditions=[[0.3], [0.5]], progress=False)
    dirs = []
    for cls in (CVAE, CGAN):
        path = tmp_path / cls.name
        cls(hidden=[16, 16], batch=64).fit(data, epochs=2, seed=0, progress=False, out=path)
        dirs.append(path)
    out = tmp_path / "bench"
    results = run_sampling_bench(dirs, out, samples=60, reference_rows=60, repeats=1, counts=(10, 100),
                                 seen=[0.3, 0.5], unseen=[0.4], progress=False)
    assert set(results["models"]) == {"cvae", "cgan"}
    for entry in results["models"].values():
        assert set(entry["time_ms"]) == {"10", "100"} and all(t > 0 for t in entry["time_ms"].values())
        for r in entry["per_condition"].values():
            assert 0 <= r["raw"] <= r["refined"] <= 1 and 0 <= r["recall"] <= 1
    assert json.loads((out / "results.json").read_text())["seen"] == [0.3, 0.5]
    assert "| 100 |" in (out / "table.md").read_text()
    for png in ("fig2_samples.png", "residuals.png", "coverage.png"):
        assert (out / png).read_bytes()[:4] == b"\x89PNG"


def test_default_conditions_on_a_two_dimensional_grid():
    from manifoldgen.bench.sampling import default_grid_conditions

    grid = np.array([[d, p] for d in (0.2, 0.3, 0.4, 0.5) for p in (-0.5, 0.0, 0.5)])
    seen, unseen = default_grid_conditions(grid)
    assert seen == [(0.2, -0.5), (0.3, 0.0), (0.4, 0.0), (0.5, 0.5)] and all(list(y) in grid.tolist() for y in seen)
    assert unseen == [(0.35, 0.0), (0.3, 0.25), (0.35, 0.25)]
    assert not any(list(y) in grid.tolist() for y in unseen)
