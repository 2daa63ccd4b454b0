"""Training loop: bad datasets, checkpoints and exact resume, the train command."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.data import collect
from manifoldgen.dataset import Dataset
from manifoldgen.errors import ManifoldgenError
from manifoldgen.models import CVAE, ConditionalFlowMatching, load_model
from manifoldgen.selection import BLEND_SHARE
from manifoldgen.tasks import task_from_meta
from manifoldgen.training import check_dataset, manifold_dimension, train

TINY = {"hidden": [16, 16], "batch": 16, "patience": 100}
runner = CliRunner()


@pytest.fixture(scope="module")
def tiny(panda_task) -> Dataset:
    return collect(panda_task, 60, seed=5, conditions=[[0.3], [0.5]], progress=False)


def test_bad_datasets_are_refused(tiny):
    task = task_from_meta(tiny.meta)
    nan = Dataset(tiny.q.copy(), tiny.y.copy(), tiny.meta)
    nan.q[3, 2] = np.nan
    with pytest.raises(ManifoldgenError, match="NaN"):
        check_dataset(nan, task)
    single = Dataset(tiny.q, np.full_like(tiny.y, 0.3), tiny.meta)
    with pytest.raises(ManifoldgenError, match="single condition value"):
        CVAE(**TINY).fit(single, epochs=1, progress=False)
    with pytest.raises(ManifoldgenError, match="at least"):
        check_dataset(Dataset(tiny.q[:3], tiny.y[:3], tiny.meta), task)
    with pytest.raises(ManifoldgenError, match="epochs must be positive"):
        CVAE(**TINY).fit(tiny, epochs=0, progress=False)
    reversed_joints = Dataset(tiny.q, tiny.y, {**tiny.meta, "joints": tiny.meta["joints"][::-1]})
    with pytest.raises(ManifoldgenError, match="not its task's planning group"):
        check_dataset(reversed_joints, task)
    extra = Dataset(tiny.q, np.concatenate([tiny.y, tiny.y], axis=1), tiny.meta)
    with pytest.raises(ManifoldgenError, match="2 condition columns but its task has 1"):
        check_dataset(extra, task)
    off = Dataset(tiny.q + np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3]), tiny.y, tiny.meta)
    with pytest.raises(ManifoldgenError, match="does not satisfy its task's constraint"):
        CVAE(**TINY).fit(off, epochs=1, progress=False)


def test_outputs_and_early_stopping(tiny, tmp_path):
    out = tmp_path / "m"
    log = CVAE(**{**TINY, "patience": 1, "lr": 0.5}).fit(tiny, epochs=30, seed=0, progress=False, out=out)
    assert log.stopped_early and len(log.history) < 30
    assert log.best_val == min(h["val"] for h in log.history)
    assert {"model.json", "model.safetensors", "loss.png", "training.json"} <= {p.name for p in out.iterdir()}
    assert not (out / "checkpoint.safetensors").exists()
    assert json.loads((out / "training.json").read_text())["best_epoch"] == log.best_epoch
    assert (out / "loss.png").read_bytes()[:4] == b"\x89PNG"


def test_interrupted_run_resumes_to_the_same_model(tiny, tmp_path, monkeypatch):
    whole = CVAE(**TINY)
    whole.fit(tiny, epochs=4, seed=2, progress=False, out=tmp_path / "whole")

    calls = {"n": 0}
    original = CVAE._train_step

    def interrupted(self, *args):
        calls["n"] += 1
        if calls["n"] == 15:  # inside epoch 3 (6 steps per epoch)
            raise KeyboardInterrupt
        return original(self, *args)

    monkeypatch.setattr(CVAE, "_train_step", interrupted)
    with pytest.raises(ManifoldgenError, match="--resume"):
        CVAE(**TINY).fit(tiny, epochs=4, seed=2, progress=False, out=tmp_path / "cut")
    monkeypatch.setattr(CVAE, "_train_step", original)
    assert (tmp_path / "cut" / "checkpoint.safetensors").exists()
    with pytest.raises(ManifoldgenError, match="pass --resume"):
        CVAE(**TINY).fit(tiny, epochs=4, seed=2, progress=False, out=tmp_path / "cut")
    with pytest.raises(ManifoldgenError, match="another dataset, model, seed"):
        CVAE(**TINY).fit(tiny, epochs=4, seed=3, progress=False, out=tmp_path / "cut", resume=True)
    log = CVAE(**TINY).fit(tiny, epochs=4, seed=2, progress=False, out=tmp_path / "cut", resume=True)
    assert log.resumed_at == 2 and len(log.history) == 4
    a, b = load_model(tmp_path / "whole"), load_model(tmp_path / "cut")
    for key, value in a.state_tensors().items():
        torch.testing.assert_close(b.state_tensors()[key], value, rtol=0, atol=0)
    with pytest.raises(ManifoldgenError, match="no checkpoint"):
        train(CVAE(**TINY), tiny, task=task_from_meta(tiny.meta), epochs=4, seed=2, progress=False,
              out=tmp_path / "cut", resume=True)


def test_the_learning_rate_follows_the_model_s_schedule(tiny, monkeypatch):
    """``cosine`` decays the rate along half a cosine, step by step over all epochs; ``constant`` (the default on
    few rows, as these) keeps it; an unknown schedule is refused, naming the known ones."""
    seen = []
    original = CVAE._train_step

    def recording(self, q, y, y_free, optimizers, generator):
        seen.append(optimizers[0].lr)
        return original(self, q, y, y_free, optimizers, generator)

    monkeypatch.setattr(CVAE, "_train_step", recording)
    CVAE(**TINY, lr=0.002, lr_schedule="cosine").fit(tiny, epochs=3, seed=0, progress=False)
    steps = len(seen)
    np.testing.assert_allclose(seen, [0.001 * (1 + np.cos(np.pi * i / steps)) for i in range(steps)], rtol=1e-12)
    assert seen[0] == 0.002 and 0 < seen[-1] < 0.002 * 0.01
    seen.clear()
    CVAE(**TINY, lr=0.002).fit(tiny, epochs=2, seed=0, progress=False)
    assert set(seen) == {0.002}
    with pytest.raises(ManifoldgenError, match="lr_schedule='linear' of model 'cvae' must be constant or cosine"):
        CVAE(lr_schedule="linear")


def test_train_command(tiny, tmp_path):
    data = tmp_path / "tiny.npz"
    tiny.save(data)
    out = tmp_path / "model"
    result = runner.invoke(app, ["train", str(data), "--model", "cvae", "--seed", "0", "-o", str(out),
                                 "--epochs", "2"])
    assert result.exit_code == 0, result.output
    assert "trained cvae" in result.output
    assert load_model(out).meta["joints"] == tiny.meta["joints"]
    bad = runner.invoke(app, ["train", str(data), "--model", "cvea", "-o", str(out)])
    assert bad.exit_code == 2 and "did you mean cvae" in bad.output
    resume = runner.invoke(app, ["train", str(data), "-o", str(tmp_path / "new"), "--resume"])
    assert resume.exit_code == 2 and "no checkpoint" in resume.output


def test_a_latent_below_the_manifold_dimension_is_warned(tiny):
    assert manifold_dimension(task_from_meta(tiny.meta), tiny.q[:3], tiny.y[:3]) == 3  # panda, 7 joints - 4 pose rows
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        CVAE(**TINY).fit(tiny, epochs=1, progress=False)  # latent 3 = the dimension: no warning
    with pytest.warns(UserWarning, match="latent 2 is below the constraint manifold's dimension 3.*--set latent=3"):
        CVAE(**{**TINY, "latent": 2}).fit(tiny, epochs=1, progress=False)


def test_sizes_not_given_follow_the_data_and_given_ones_are_kept(tiny):
    sized = CVAE(batch=16, patience=100)
    sized.fit(tiny, epochs=1, seed=0, progress=False)
    # panda pose: 7 joints, dimension 3; the CVAE's layers at least 256 wide (width_for(7) = 128)
    assert sized.config["latent"] == 3 and sized.config["hidden"] == [256, 256, 256]
    assert sized.config["prior_hidden"] == [64, 64]  # the prior's width is its own
    assert sized.config["encoder_hidden"] == [64, 64] and sized.nets["encoder"][0].out_features == 64
    wide = CVAE()
    wide.size_for(39, 27, 9000)  # a whole-body robot: two layers of the others' width, the encoder's too
    assert wide.config["hidden"] == [384, 384] == wide.config["encoder_hidden"] and wide.config["latent"] == 27
    narrow = CVAE(encoder_hidden=[32])
    narrow.size_for(39, 27, 9000)
    assert narrow.config["encoder_hidden"] == [32]  # given: kept
    flow = ConditionalFlowMatching(batch=16, patience=100)
    flow.fit(tiny, epochs=1, seed=0, progress=False)
    assert flow.config["hidden"] == [128, 128]
    kept = CVAE(latent=5, hidden=[16], batch=16, patience=100)
    kept.fit(tiny, epochs=1, seed=0, progress=False)
    assert kept.config["latent"] == 5 and kept.config["hidden"] == [16]


def test_the_cvae_decays_its_rate_on_enough_rows_unless_told_otherwise(tiny, monkeypatch):
    from manifoldgen.models.cvae import DECAY_BATCHES, DECAYED_EPOCHS

    enough, few = DECAY_BATCHES * 256, DECAY_BATCHES * 256 - 1  # at the default batch of 256 rows
    for model, rows, expected in ((CVAE(), enough, (DECAYED_EPOCHS, "cosine")), (CVAE(), few, (60, "constant")),
                                  (CVAE(epochs=60), enough, (60, "cosine")),  # the epochs given, the rate decays
                                  (CVAE(lr_schedule="constant"), enough, (60, "constant")),
                                  (CVAE(batch=512), enough, (60, "constant"))):
        model.size_for(7, 3, rows)
        assert (model.config["epochs"], model.config["lr_schedule"]) == expected, (model.given, rows)
    rates = []
    original = CVAE._train_step

    def recording(self, q, y, y_free, optimizers, generator):
        rates.append(optimizers[0].lr)
        return original(self, q, y, y_free, optimizers, generator)

    monkeypatch.setattr(CVAE, "_train_step", recording)
    log = CVAE(**{**TINY, "batch": 3}).fit(tiny, seed=0, progress=False)  # 108 training rows: 36 batches
    assert log.epochs == DECAYED_EPOCHS == 40 and len(log.history) <= 40
    assert rates[0] == CVAE.defaults["lr"] and rates[-1] < rates[len(rates) // 2] < rates[0]  # trained decaying


def test_a_model_records_the_refinement_its_samples_need(tiny, tmp_path):
    from manifoldgen.constraints import project
    from manifoldgen.training import REFINE_LADDER, REFINE_SHARE

    model = CVAE(**TINY)
    model.fit(tiny, epochs=3, seed=0, progress=False, out=tmp_path / "m")
    loaded = load_model(tmp_path / "m")
    assert loaded.refine == model.refine and loaded.refine in REFINE_LADDER
    y = np.array([0.3])
    rows = loaded.sample(y, 512, torch.Generator().manual_seed(9))
    constraint = task_from_meta(tiny.meta).constraint
    rate = constraint.satisfied(project(constraint, rows, y, max_iters=loaded.refine).q, y)
    top = constraint.satisfied(project(constraint, rows, y, max_iters=REFINE_LADDER[-1]).q, y)
    assert rate.mean() >= REFINE_SHARE * top.mean() - 0.1  # the held-out conditions' rate, here at one condition


def test_auto_trains_every_candidate_and_keeps_the_rule_s_choice(tiny, tmp_path):
    out = tmp_path / "auto"
    result = runner.invoke(app, ["train", str(_saved(tiny, tmp_path)), "--seed", "0", "-o", str(out), "--epochs", "2"])
    assert result.exit_code == 0, result.output
    table = json.loads((out / "selection.json").read_text())["candidates"]
    assert [row["model"] for row in table][:2] == ["cvae", "cfm"] and sum(row["chosen"] for row in table) == 1
    by_accuracy, by_recall = (max(table[:2], key=lambda row: row[key])["model"] for key in ("accuracy", "recall"))
    blends = [f"{by_accuracy}+{by_recall}"] if by_accuracy != by_recall else []  # the accurate one's rows blended
    assert [row["model"] for row in table][2:] == blends and all(row["blend"] == BLEND_SHARE for row in table[2:])
    best = max(row["recall"] for row in table)
    chosen = next(row for row in table if row["chosen"])
    assert chosen["recall"] >= best - 0.1
    assert all(row["accuracy"] <= chosen["accuracy"] for row in table if row["recall"] >= best - 0.1)
    assert load_model(out).label == chosen["model"] and f"chosen {chosen['model']}" in result.output
    assert (out / "blend").is_dir() == ("+" in chosen["model"])
    assert all(load_model(out / "candidates" / name).label == name for name in blends)
    refused = runner.invoke(app, ["train", str(_saved(tiny, tmp_path)), "-o", str(out), "--set", "latent=2"])
    assert refused.exit_code == 2 and "name it with --model" in refused.output


def _saved(dataset: Dataset, folder) -> str:
    path = folder / "tiny.npz"
    if not path.exists():
        dataset.save(path)
    return str(path)


@pytest.mark.slow
def test_candidates_trained_in_parallel_are_the_sequential_ones(tiny, tmp_path):
    from manifoldgen.selection import select_model

    _, one, _ = select_model(tiny, tmp_path / "one", seed=4, epochs=1, progress=False, workers=1,
                             race_scenes=False)
    _, two, _ = select_model(tiny, tmp_path / "two", seed=4, epochs=1, progress=False, workers=2,
                             race_scenes=False)
    assert [{k: v for k, v in row.items() if k != "seconds"} for row in one] == \
        [{k: v for k, v in row.items() if k != "seconds"} for row in two]
    for name in ("cvae", "cfm"):
        a, b = (load_model(tmp_path / run / "candidates" / name) for run in ("one", "two"))
        for key, value in a.state_tensors().items():
            torch.testing.assert_close(b.state_tensors()[key], value, rtol=0, atol=0)


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_auto_races_the_candidates_on_the_task_scenes_and_keeps_the_winner(tmp_path, workers):
    """In one process, or with the second candidate trained, scored and raced in a child that races projection
    too: every entry raced on every scene, the winner kept, every candidate's loss curves drawn."""
    from manifoldgen.selection import PROJECTION, RACE_SEEDS, select_model
    from manifoldgen.tasks import get_task

    task = get_task("sphere")
    data = collect(task, 400, seed=3, progress=False)
    model, table, raced = select_model(data, tmp_path / "m", seed=1, epochs=2, progress=False, workers=workers,
                                       task=task)
    blends = [row["model"] for row in table if "blend" in row]  # the most accurate with the most covering's rows
    assert blends in ([], ["cvae+cfm"], ["cfm+cvae"])
    assert [row["label"] for row in raced] == ["cvae", "cfm", *blends, PROJECTION]
    assert all(row["runs"] == RACE_SEEDS * len(task.scenes) and row["cpu"] > 0 for row in raced)
    winner = max(raced, key=lambda r: (r["solved"], -r["cpu"]))
    assert winner["chosen"] and sum(row["chosen"] for row in raced) == 1
    saved = load_model(tmp_path / "m")
    assert saved.label == winner["model"] and saved.mix == winner["mix"]
    assert json.loads((tmp_path / "m" / "selection.json").read_text())["race"] == raced
    assert all((tmp_path / "m" / "candidates" / name / "loss.png").stat().st_size > 0 for name in ("cvae", "cfm"))


def test_a_step_with_a_non_finite_loss_is_skipped_and_a_divergence_keeps_the_best_epoch(tiny, monkeypatch):
    """A NaN loss leaves the weights and the optimiser as they were (the step counts as skipped); a validation score
    that is not finite after good epochs stops training there and keeps the best epoch before it."""
    model = CVAE(**TINY)
    real_losses, calls = CVAE._losses, []

    def nan_once(self, *args):
        calls.append(1)
        losses = real_losses(self, *args)
        return {**losses, "loss": losses["loss"] * float("nan")} if len(calls) == 2 else losses

    monkeypatch.setattr(CVAE, "_losses", nan_once)
    log = model.fit(tiny, epochs=1, seed=0, progress=False)
    assert log.history[0]["train"]["skipped"] > 0 and np.isfinite(log.best_val)
    assert all(torch.isfinite(p).all() for p in model.nets.parameters())
    monkeypatch.setattr(CVAE, "_losses", real_losses)

    real_val, epochs = CVAE._validation_loss, []

    def diverge_at_three(self, *args):
        epochs.append(1)
        return float("nan") if len(epochs) == 3 else real_val(self, *args)

    monkeypatch.setattr(CVAE, "_validation_loss", diverge_at_three)
    model = CVAE(**TINY)
    log = model.fit(tiny, epochs=6, seed=0, progress=False)
    assert log.diverged_at == 3 and log.stopped_early and len(log.history) == 2 and log.best_epoch in (1, 2)
    assert np.isfinite(model.sample([0.4], 20)).all()
    monkeypatch.setattr(CVAE, "_validation_loss", lambda self, *a: float("nan"))
    with pytest.raises(ManifoldgenError, match="diverged at epoch 1"):
        CVAE(**TINY).fit(tiny, epochs=3, seed=0, progress=False)
