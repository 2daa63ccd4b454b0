"""ModelSampler (Algorithm 1 with a model) and the sample command, checked by pinocchio alone."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from typer.testing import CliRunner

from manifoldgen.cli import app
from manifoldgen.collision import CollisionChecker
from manifoldgen.data import collect
from manifoldgen.dataset import Dataset
from manifoldgen.errors import ManifoldgenError
from manifoldgen.models import CVAE, load_model
from manifoldgen.robot import resolve_robot
from manifoldgen.sampling import ModelSampler
from manifoldgen.space import ConstrainedSpace
from manifoldgen.tasks import get_task

runner = CliRunner()


@pytest.fixture(scope="module")
def model_dir(panda_task, tmp_path_factory):
    data = collect(panda_task, 150, seed=4, conditions=[[0.3], [0.5]], progress=False)
    path = tmp_path_factory.mktemp("model")
    CVAE(hidden=[32, 32], batch=64).fit(data, epochs=8, seed=0, progress=False, out=path)
    return path


def test_model_sampler_returns_only_valid_samples(model_dir, panda_task):
    model = load_model(model_dir)
    checker = CollisionChecker(panda_task.robot)
    space = ConstrainedSpace(panda_task.constraint, [0.4], checker)
    sampler = ModelSampler(space, model, refine=5, batch=128, seed=1)
    assert sampler.decoder is not None  # the CVAE's decoder runs in the compiled core
    q = sampler.sample_many(40)
    assert q.shape == (40, 7)
    assert panda_task.constraint.satisfied(q, [0.4]).all()
    assert not checker.in_collision(q).any()
    assert sampler.stats.accepted == 40 and sampler.stats.refined == sampler.stats.generated
    again = ModelSampler(space, model, refine=5, batch=128, seed=1)
    np.testing.assert_array_equal(again.sample_many(40), q)


@pytest.mark.slow
def test_a_model_directory_samples_in_the_core_as_the_torch_model_does(model_dir, panda_task):
    """open_model reads the files without torch; its core decoder draws the torch model's decoder's rows, and a
    plan through it never loads torch (checked in a fresh interpreter)."""
    import subprocess
    import sys

    from manifoldgen.models import open_model

    saved, model = open_model(model_dir), load_model(model_dir)
    assert saved.decoder == model.decoder_spec() == {"net": "decoder", "law": "normal", "noise": 3, "steps": 0,
                                                     "layers": 3, "prior": {"net": "prior", "steps": 4, "layers": 3}}
    assert np.array_equal(saved.native_decoder().sample(np.array([0.4]), 50, 7),
                          model.native_decoder().sample(np.array([0.4]), 50, 7))
    code = ("import sys; from manifoldgen.cli import app; sys.argv = ['manifoldgen', 'plan', 'pose', "
            "'--scene', 'wall', '--sampler', 'model:" + str(model_dir) + "', '--time', '20', '-o', "
            "'" + str(model_dir.parent / "p.npz") + "']\ntry:\n    app()\nexcept SystemExit as e:\n"
            "    assert not e.code, e.code\nassert 'torch' not in sys.modules")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def test_model_sampler_refuses_another_robot(model_dir):
    model = load_model(model_dir)
    pr2 = get_task("pose", "pr2")
    with pytest.raises(ManifoldgenError, match="made for another task: robot panda .* vs pr2"):
        ModelSampler(ConstrainedSpace(pr2.constraint, [0.8]), model)


def test_a_model_is_refused_for_another_constraint_value_not_for_last_bits(model_dir, panda_task):
    """Numbers of the constraint's spec computed from kinematics may differ in their last bits between versions."""
    from manifoldgen.provenance import check_made_for
    meta = load_model(model_dir).meta
    spec = meta["constraint"]
    key = next(k for k, v in spec.items() if isinstance(v, list) and v and isinstance(v[0], list))  # e.g. rotation
    for scale, refused in ((1 + 1e-13, False), (1 + 1e-3, True)):
        changed = {**meta, "constraint": {**spec, key: (np.array(spec[key]) * scale + 1e-14).tolist()}}
        if refused:
            with pytest.raises(ManifoldgenError, match=f"made for another task: constraint pose differs in {key}"):
                check_made_for(changed, panda_task.constraint, "model")
        else:
            check_made_for(changed, panda_task.constraint, "model")


def _pinocchio_valid(meta: dict, q: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Independent checker: pinocchio FK and log3 from the file's meta only."""
    urdf, _ = resolve_robot(meta["robot"])
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    spec = meta["constraint"]
    frame = model.getFrameId(spec["frame"])
    target = np.array(spec["rotation"])
    axes = ["xyz".index(a) for a in spec["position_axes"]]
    ok = np.zeros(len(q), bool)
    base = pin.neutral(model)
    for name, value in meta["locked"].items():
        base[model.joints[model.getJointId(name)].idx_q] = value
    for b in range(len(q)):
        full = base.copy()
        for j, name in enumerate(meta["joints"]):
            full[model.joints[model.getJointId(name)].idx_q] = q[b, j]
        pin.framesForwardKinematics(model, data, full)
        M = data.oMf[frame]
        pos = np.abs(M.translation[axes] - y[b])
        rot = np.abs(pin.log3(target.T @ M.rotation))
        limits = np.all(full >= model.lowerPositionLimit - 1e-9) and np.all(full <= model.upperPositionLimit + 1e-9)
        ok[b] = (pos.max() <= spec["position_tolerance"] and rot.max() <= spec["orientation_tolerance"]
                 and limits)
    return ok


@pytest.mark.parametrize("refine", [0, 3])
def test_sample_command_rates_match_an_independent_checker(model_dir, tmp_path, refine):
    out = tmp_path / "s.npz"
    result = runner.invoke(app, ["sample", str(model_dir), "--condition", "0.4", "-n", "300", "--seed", "2",
                                 "--refine", str(refine), "-o", str(out)])
    assert result.exit_code == 0, result.output
    data = Dataset.load(out)
    assert data.meta["rows"] == ("refined" if refine else "raw")
    assert data.q.shape == (300, 7) and np.all(data.y == 0.4)
    rate = _pinocchio_valid(data.meta, data.q, data.y).mean()
    key = "refined_valid_rate" if refine else "raw_valid_rate"
    assert data.meta[key] == pytest.approx(rate, abs=1 / 300)
    shown = f"{rate:.2%}"
    assert shown in result.output
    if refine:
        assert rate > 0.9


def test_sample_command_errors(model_dir, tmp_path):
    out = str(tmp_path / "s.npz")
    zero = runner.invoke(app, ["sample", str(model_dir), "--condition", "0.4", "-n", "0", "-o", out])
    assert zero.exit_code == 2 and "positive" in zero.output
    warn = runner.invoke(app, ["sample", str(model_dir), "--condition", "0.65", "-n", "10", "-o", out])
    assert warn.exit_code == 0 and "outside the trained range" in warn.output and "0.3, 0.5" in warn.output
    strict = runner.invoke(app, ["sample", str(model_dir), "--condition", "0.65", "-n", "10", "--strict", "-o", out])
    assert strict.exit_code == 2 and "outside the trained range" in strict.output
    other = runner.invoke(app, ["sample", str(model_dir), "--condition", "0.8", "--task", "pose", "--robot", "pr2",
                                "-n", "10", "-o", out])
    assert other.exit_code == 2 and "robot panda" in other.output and "vs pr2" in other.output
    missing = runner.invoke(app, ["sample", str(tmp_path), "--condition", "0.4", "-n", "10", "-o", out])
    assert missing.exit_code == 2 and "missing model.json" in missing.output


def test_model_spec_takes_whichever_model_a_directory_holds(model_dir, panda_task):
    from manifoldgen.specs import make_sampler

    space = ConstrainedSpace(panda_task.constraint, [0.4])
    sampler = make_sampler(f"model:{model_dir},batch=64", space, seed=1)
    assert isinstance(sampler, ModelSampler) and sampler.model.name == "cvae"
    assert sampler.refine == load_model(model_dir).refine  # the refinement the model recorded
    with pytest.raises(ManifoldgenError, match="holds a cvae model, not cfm"):
        make_sampler(f"cfm:{model_dir}", space, seed=1)


def test_a_dearer_model_draws_fewer_pool_rows_in_both_searches(model_dir, panda_task):
    """The pool settings and a model sampler's batch count rows of the shipped panda CVAE's cost; a model whose
    rows cost more multiply-adds gets fewer in proportion, in the Python search and in the core's alike."""
    from manifoldgen.planning import RRTConnect, RRTConnectSettings
    from manifoldgen.planning.rrt_connect import core_settings
    from manifoldgen.sampling import REFERENCE_ROW_COST

    model = load_model(model_dir)  # [latent 3, height] -> 32 -> 32 -> 7, after the prior [z, y, t] -> 64 -> 64 -> 3
    space = ConstrainedSpace(panda_task.constraint, [0.4])
    sampler = ModelSampler(space, model, seed=1)
    prior = 2 * 4 * (5 * 64 + 64 * 64 + 64 * 3)  # 4 steps of two passes each (Heun)
    assert sampler.row_cost == model.row_cost() == 4 * 32 + 32 * 32 + 32 * 7 + prior
    sampler.row_cost = REFERENCE_ROW_COST
    settings = RRTConnectSettings(pool=2048, pool_batch=256)
    assert RRTConnect(space, sampler, settings=settings).pool_rows() == (2048, 256)  # as cheap as the reference
    sampler.row_cost = 10 * REFERENCE_ROW_COST
    planner = RRTConnect(space, sampler, settings=settings)
    assert planner.pool_rows() == (205, 26)
    native = core_settings(planner, 0)
    assert (native.pool, native.pool_batch) == (205, 26)
    sampler.stats.batches = 10  # its batches stop growing at a tenth of 1,024 rows
    assert sampler._batch_rows() == 102
