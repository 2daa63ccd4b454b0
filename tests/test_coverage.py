"""Query coverage: anchors, modes and gaps; collection seeded around a task's scenes; a model sampler that misses
a query's start or goal mixes in projected uniform rows."""

from __future__ import annotations

import numpy as np
import pytest

from manifoldgen.coverage import Anchors, gaps, missed, modes, spacing
from manifoldgen.scene import task_anchors
from manifoldgen.data import collect
from manifoldgen.models import load_model, pretrained_model_dir
from manifoldgen.sampling import MIX_AFTER, MIX_MAX, MIX_MISSED, PROJECT_ITERS, ModelSampler
from manifoldgen.space import ConstrainedSpace


def test_modes_find_separated_clusters_and_their_shares():
    rng = np.random.default_rng(0)
    rows = np.concatenate([rng.normal(0.0, 0.1, (700, 4)), rng.normal(3.0, 0.1, (300, 4))])
    found = modes(rows)
    assert [round(m["share"], 1) for m in found] == [0.7, 0.3]
    np.testing.assert_allclose(found[1]["centre"], 3.0, atol=0.05)
    assert len(modes(rng.normal(0.0, 1.0, (1000, 3)))) == 1  # one blob is one mode


def test_gaps_and_misses():
    rows = np.array([[0.0, 0.0], [1.0, 0.0]])
    np.testing.assert_allclose(gaps(rows, np.array([[0.0, 2.0], [1.0, 0.5]])), [2.0, 0.5])
    assert spacing(rows) == pytest.approx(1.0)
    assert list(missed(np.array([0.4, 2.0, 2.0]), np.array([0.01, 1.0, 0.1]))) == [False, False, True]


@pytest.fixture(scope="module")
def wall_rows(panda_task):
    anchors = task_anchors(panda_task)
    wall = [i for i, label in enumerate(anchors.labels) if label.startswith("wall ")]
    wall_anchors = Anchors(anchors.q[wall], anchors.y[wall], [anchors.labels[i] for i in wall])
    y = wall_anchors.y[:1]
    seeded = collect(panda_task, 150, seed=3, conditions=y, progress=False, anchors=wall_anchors)
    uniform = collect(panda_task, 150, seed=3, conditions=y, progress=False)
    return wall_anchors, seeded, uniform


def test_task_anchors_are_every_scene_start_and_goal_on_the_manifold(panda_task):
    anchors = task_anchors(panda_task)
    assert sorted(anchors.labels) == sorted(f"{s} {e}" for s in panda_task.scenes for e in ("start", "goal"))
    for q, y in zip(anchors.q, anchors.y):
        assert panda_task.constraint.satisfied(q[None], y[None])[0]


def test_collection_seeded_around_anchors_comes_nearer_to_them(wall_rows, panda_task):
    anchors, seeded, uniform = wall_rows
    assert seeded.meta["anchors"] == anchors.to_meta() and "anchors" not in uniform.meta
    assert panda_task.constraint.satisfied(seeded.q, seeded.y).all()
    near, far = gaps(seeded.q, anchors.q), gaps(uniform.q, anchors.q)
    assert (near < far).all() and near.max() < 0.5 * far.min()
    report = seeded.meta["coverage"]
    assert [a["label"] for a in report["anchors"]] == anchors.labels
    np.testing.assert_allclose([a["gap"] for a in report["anchors"]], near, atol=1e-4)
    assert 0 < sum(next(iter(report["modes"].values()))) <= 1.0  # clusters under 2 % of the rows are not modes


@pytest.fixture(scope="module")
def shipped(panda_task):
    model = load_model(pretrained_model_dir())
    y = np.array([0.5])
    space = ConstrainedSpace(panda_task.constraint, y)
    return model, space


def _far_configuration(model, space, seed: int) -> np.ndarray:
    """A configuration on the manifold far from every one of 4000 model samples (an IK branch it misses)."""
    import torch

    samples = model.sample(space.y, 4000, torch.Generator().manual_seed(seed))
    rng = np.random.default_rng(seed)
    projected = space.project(space.robot.sample_uniform(2000, rng), max_iters=PROJECT_ITERS)
    on = projected.q[projected.converged & space.valid(projected.q)]
    return on[np.argmax(gaps(samples, on))]


def test_a_model_that_misses_the_query_mixes_in_projected_rows_and_says_why(shipped):
    model, space = shipped
    sampler = ModelSampler(space, model, seed=0)
    far = _far_configuration(model, space, 1)
    note = sampler.begin_query(far, far)
    assert "misses an IK branch" in note and sampler.mix() == MIX_MISSED
    assert sampler.lazy_refine == PROJECT_ITERS
    rows = sampler.candidates(2000)
    assert abs(sampler.stats.mixed - MIX_MISSED * 2000) < 80
    assert space.valid(rows).mean() > 0.5  # the uniform rows were projected fully, the model rows refined
    covered = ModelSampler(space, model, seed=1).sample_many(1)[0]  # a model row: a query the model covers
    generated = sampler.stats.generated
    assert sampler.begin_query(covered, covered) == "" and sampler.mix() == 0.0
    assert sampler.lazy_refine == sampler.refine
    assert sampler.stats.generated == generated  # measured on the rows drawn when the sampler was made


def test_a_query_that_runs_long_mixes_in_projected_rows_gradually(shipped):
    model, space = shipped
    sampler = ModelSampler(space, model, seed=0)
    q = sampler.sample_many(1)[0]
    sampler.begin_query(q, q)
    sampler.raw(MIX_AFTER)
    assert sampler.stats.mixed == 0 and sampler.mix() == 0.0
    sampler.raw(MIX_AFTER // 2)
    assert sampler.mix() == pytest.approx(MIX_MAX / 2)
    sampler.raw(MIX_AFTER)
    assert sampler.mix() == MIX_MAX and 0 < sampler.stats.mixed < MIX_MAX * 2.5 * MIX_AFTER


def test_a_model_whose_race_chose_projection_stands_for_the_projection_sampler(shipped):
    import copy

    from manifoldgen.sampling import ProjectionSampler, model_sampler
    model, space = shipped
    projection = copy.copy(model)
    projection.mix = 1.0
    chosen = model_sampler(space, projection, seed=3)
    assert type(chosen) is ProjectionSampler
    np.testing.assert_array_equal(chosen.sample_many(5), ProjectionSampler(space, seed=3).sample_many(5))
    assert type(model_sampler(space, model, seed=3)) is ModelSampler  # the race kept the model (mix 0 or none)
    assert type(model_sampler(space, projection, refine=5, seed=3)) is ModelSampler  # refinement asks for the model
