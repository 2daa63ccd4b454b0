"""Contract test over every registered model, plus model files and the torch kinematics."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch

from manifoldgen.data import collect
from manifoldgen.dataset import Dataset
from manifoldgen.errors import ManifoldgenError
from manifoldgen.models import MODELS, load_model, pretrained_model_dir
from manifoldgen.models.base import document_checksum
from manifoldgen.models.files import MODEL_NETS
from manifoldgen.tasks import get_task

TINY = {"hidden": [32, 32], "batch": 32}


@pytest.fixture(scope="module")
def task():
    return get_task("pose", "panda")


@pytest.fixture(scope="module")
def tiny(task) -> Dataset:
    """200 valid panda rows at heights 0.3 and 0.5 m."""
    return collect(task, 100, seed=3, conditions=[[0.3], [0.5]], progress=False)


def _hyper(name: str) -> dict:
    extra = {"critic_hidden": [32, 32]} if name in ("cgan", "wgan") else {}
    if name == "flow":
        extra = {"transforms": 2, "bins": 4}
    if name == "cfm":
        extra = {"steps": 4, "penalty_fraction": 1.0, "lr": 0.01}
    return {**TINY, **extra}


@pytest.fixture(scope="module")
def trained(tiny, tmp_path_factory):
    """Each model trained for a few epochs on the tiny set, saved to a directory."""
    out = {}
    for name, cls in ((n, MODELS.get(n)) for n in MODELS.names()):
        model = cls(**_hyper(name))
        log = model.fit(tiny, epochs=6, seed=1, progress=False)
        path = tmp_path_factory.mktemp(name)
        model.save(path)
        out[name] = (model, log, path)
    return out


@pytest.mark.parametrize("name", MODELS.names())
def test_model_contract(name, trained, tiny, task):
    model, log, path = trained[name]
    # shapes, dtype, limits
    q = model.sample([0.3], 50, torch.Generator().manual_seed(0))
    assert q.shape == (50, 7) and q.dtype == np.float64
    assert task.robot.within_limits(q).all()
    assert model.sample(np.array([[0.3], [0.5], [0.4]]), 3).shape == (3, 7)
    # determinism for a generator seed
    again = model.sample([0.3], 50, torch.Generator().manual_seed(0))
    np.testing.assert_array_equal(q, again)
    # save/load round trip gives identical samples
    loaded = load_model(path)
    assert type(loaded) is type(model) and loaded.meta == model.meta
    np.testing.assert_array_equal(loaded.sample([0.3], 50, torch.Generator().manual_seed(0)), q)
    # the networks its files hold are the ones a reader without torch allows (models/files.py)
    assert tuple(sorted(model.nets)) == MODEL_NETS[name]
    # conditioning changes the output
    other = model.sample([0.5], 50, torch.Generator().manual_seed(0))
    assert np.abs(other - q).max() > 1e-3
    # training reduced the loss: the constraint residual of samples (every model), and the
    # validation score of the likelihood and regression models (a GAN's adversarial losses need not fall)
    residual = [h["train"]["residual"] for h in log.history]
    assert residual[-1] < residual[0]
    if name in ("cvae", "flow", "cfm"):
        vals = [h["val"] for h in log.history]
        assert min(vals[1:]) < vals[0]
    # training is deterministic for a seed
    twin = MODELS.get(name)(**_hyper(name))
    twin.fit(tiny, epochs=2, seed=1, progress=False)
    first = MODELS.get(name)(**_hyper(name))
    first.fit(tiny, epochs=2, seed=1, progress=False)
    for key, value in first.state_tensors().items():
        torch.testing.assert_close(twin.state_tensors()[key], value, rtol=0, atol=0)


def test_the_cvae_prior_learns_the_posterior(tiny):
    """The CVAE's prior is trained: its flow-matching loss to the trained encoder's posterior samples is below that
    of the same network untrained (so a prior the training left alone would fail)."""
    from manifoldgen.models import CVAE
    from manifoldgen.models.base import mlp, velocity_at

    model = CVAE(**TINY, encoder_hidden=[32, 32])
    model.fit(tiny, epochs=40, seed=1, progress=False)
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        y = model.normalise_y(torch.from_numpy(tiny.y).float())
        z = model._encode(model.normalise_q(torch.from_numpy(tiny.q).float()), y, g)[2]
        z0, t = torch.randn(z.shape, generator=g), torch.rand(len(z), 1, generator=g)

        def loss(net):
            return float((velocity_at(net, (1 - t) * z0 + t * z, y, t) - (z - z0)).pow(2).sum(1).mean())

        torch.manual_seed(0)
        fresh = mlp(model.config["latent"] + model.k + 1, model.config["prior_hidden"], model.config["latent"])
        assert loss(model.nets["prior"]) < loss(fresh)  # seeded: 5.63 against 5.86


@pytest.mark.parametrize("name", MODELS.names())
def test_native_decoder_is_the_models_network(name, trained):
    """The core's copy of the sampling network decodes latent rows as torch does (float32 rounding apart; a
    velocity field integrated as the model samples it: Heun steps, then one Euler step; the CVAE's latent rows
    carried by its learned prior first), draws them from the model's law, and is deterministic for a seed; a flow
    has none (torch samples it)."""
    model = trained[name][0]
    decoder = model.native_decoder()
    if name == "flow":
        assert decoder is None
        return
    steps = model._integration_steps()
    z = decoder.latent_rows(20_000, 5)
    assert z.shape == (20_000, model.d if steps else model.config["latent"]) and z.dtype == np.float32
    if model._sampling_net()[1] == "uniform":
        assert np.abs(z).max() <= 1.0
        np.testing.assert_allclose(z.std(0), 3 ** -0.5, atol=0.01)
    else:
        np.testing.assert_allclose(z.std(0), 1.0, atol=0.02)
        assert abs(np.mean(np.abs(z) > 3) - 0.0027) < 0.001  # the normal's tails: P(|z| > 3) = 0.0027
    np.testing.assert_allclose(z.mean(0), 0.0, atol=0.02)
    y = np.array([0.4])
    with torch.inference_mode():
        net = model._sampling_net()[0]
        yn = model.normalise_y(torch.tensor(y, dtype=torch.float32)).expand(2000, 1)

        def heun(velocity, x, steps):
            h = 1.0 / steps
            for i in range(steps - 1):
                t0, t1 = torch.full((2000, 1), i * h), torch.full((2000, 1), (i + 1) * h)
                v = velocity(torch.cat([x, yn, t0], 1))
                x = x + 0.5 * h * (v + velocity(torch.cat([x + h * v, yn, t1], 1)))
            return x + h * velocity(torch.cat([x, yn, torch.full((2000, 1), 1.0 - h)], 1))

        x = torch.from_numpy(z[:2000])
        prior = model._prior_net()
        if prior is not None:  # the latent rows pass the learned prior first
            x = heun(prior[0], x, prior[1])
        x = heun(net, x, steps) if steps else net(torch.cat([x, yn], 1))
        expected = (x * model._q_std + model._q_mean).double().numpy()
    expected = np.clip(expected, model.norm["lower"], model.norm["upper"])
    np.testing.assert_allclose(decoder.decode(z[:2000], y), expected, rtol=0, atol=2e-5)
    q = decoder.sample(y, 300, 11)
    np.testing.assert_array_equal(q, decoder.decode(decoder.latent_rows(300, 11), y))
    assert np.abs(decoder.sample(y, 300, 12) - q).max() > 1e-3
    with pytest.raises(ValueError, match="latent rows must have"):
        decoder.decode(np.zeros((2, 99), np.float32), y)


@pytest.mark.slow
def test_cfm_covers_both_modes():
    """On two-mode data (the sphere task's polar caps, nothing between them) flow matching samples both caps,
    at a trained radius and between the two trained, each with at least a quarter of the samples, and few
    in the empty band between them: neither collapse onto one cap nor an average of the two."""
    full = collect(get_task("sphere"), 1500, seed=0, conditions=[[0.9], [1.1]], progress=False)
    caps = np.abs(full.q[:, 2]) > 0.6 * full.y[:, 0]
    assert 0.45 < np.mean(full.q[caps, 2] > 0) < 0.55
    model = MODELS.get("cfm")(hidden=[128, 128], batch=64, lr=3e-3)
    model.fit(Dataset(full.q[caps], full.y[caps], full.meta), epochs=30, seed=0, progress=False)
    for radius in (0.9, 1.0):
        height = model.sample([radius], 2000, torch.Generator().manual_seed(0))[:, 2] / radius
        assert np.mean(height > 0.5) >= 0.25 and np.mean(height < -0.5) >= 0.25
        assert np.mean(np.abs(height) < 0.3) < 0.15


def test_penalty_is_constraint_residual(task):
    """The training penalty is sum (F_i / tol_i)^2 of the constraint's own residual, on float32 tensors."""
    rng = np.random.default_rng(0)
    q = task.robot.sample_uniform(64, rng)
    y = np.full((64, 1), 0.4)
    expected = np.sum((task.constraint.residual(q, y) / task.constraint.tolerance) ** 2, axis=1)
    got = task.constraint.penalty(torch.as_tensor(q, dtype=torch.float32), torch.as_tensor(y, dtype=torch.float32))
    np.testing.assert_allclose(got.numpy(), expected, rtol=1e-3)


def test_unknown_hyper_parameter_and_untrained():
    with pytest.raises(ManifoldgenError, match="unknown hyper-parameter"):
        MODELS.get("cvae")(width=3)
    with pytest.raises(ManifoldgenError, match=r"penalty_fraction=1.5 of model 'cfm' must be in \(0, 1\]"):
        MODELS.get("cfm")(penalty_fraction=1.5)
    with pytest.raises(ManifoldgenError, match="not trained"):
        MODELS.get("cvae")().sample([0.3], 2)


def test_model_dir_errors(trained, tmp_path):
    _, _, path = trained["cvae"]
    with pytest.raises(ManifoldgenError, match="not found"):
        load_model(tmp_path / "nowhere")
    missing = tmp_path / "missing"
    shutil.copytree(path, missing)
    (missing / "model.safetensors").unlink()
    with pytest.raises(ManifoldgenError, match="missing model.safetensors"):
        load_model(missing)
    tampered = tmp_path / "tampered"
    shutil.copytree(path, tampered)
    doc = json.loads((tampered / "model.json").read_text())
    doc["config"]["hidden"] = [64, 64]
    (tampered / "model.json").write_text(json.dumps(doc))
    with pytest.raises(ManifoldgenError, match="do not match its checksum"):  # an edit is refused as such
        load_model(tampered)
    doc["sha256"] = document_checksum(doc)  # re-signed edits still meet the field checks
    (tampered / "model.json").write_text(json.dumps(doc))
    with pytest.raises(ManifoldgenError, match=r"config hidden = \[64, 64\], but its 'decoder' weights have \[32, 32\]"):
        load_model(tampered)
    doc["config"]["hidden"] = [32, 32]
    doc["normalisation"]["q_std"][0] = -1.0
    doc["sha256"] = document_checksum(doc)
    (tampered / "model.json").write_text(json.dumps(doc))
    with pytest.raises(ManifoldgenError, match="standard deviations must be positive"):
        load_model(tampered)
    (tampered / "model.json").write_text("{not json")
    with pytest.raises(ManifoldgenError, match="not valid JSON"):
        load_model(tampered)
    swapped = tmp_path / "swapped"
    shutil.copytree(path, swapped)
    shutil.copy(trained["cgan"][2] / "model.safetensors", swapped / "model.safetensors")
    with pytest.raises(ManifoldgenError, match="checksum"):
        load_model(swapped)


def test_pretrained_model_ships_and_samples(task):
    model = load_model(pretrained_model_dir())
    assert model.name == "cvae" and model.meta["robot"] == "panda"
    written = json.loads((pretrained_model_dir() / "model.json").read_text())["config"]
    assert {"encoder_hidden", "prior_steps"}.isdisjoint(written)  # a file from before both: loaded as it was trained
    assert model.config["encoder_hidden"] == model.config["hidden"] and model.config["prior_steps"] == 0
    assert model.nets["encoder"][0].out_features == model.config["hidden"][0] and "prior" not in model.nets
    q = model.sample([0.45], 2000, torch.Generator().manual_seed(0))
    rate = task.constraint.satisfied(q, [0.45]).mean()
    assert rate > 0.5
    native = model.native_decoder().sample(np.array([0.45]), 2000, 0)  # the planners' sampler runs this copy
    assert abs(task.constraint.satisfied(native, [0.45]).mean() - rate) < 0.05
    with pytest.raises(ManifoldgenError, match="no pretrained model"):
        pretrained_model_dir("nope")


def test_a_cvae_posterior_variance_too_large_for_float32_keeps_the_losses_finite(trained, tiny):
    """An encoder whose log-variance runs away (exp overflows float32 past 88) still gives finite losses: the
    log-variance is clamped to LOGVAR_RANGE, so one wild batch cannot turn the KL and the reconstruction infinite."""
    from manifoldgen.models.cvae import LOGVAR_RANGE
    model = MODELS.get("cvae")(**_hyper("cvae"))
    model.fit(tiny, epochs=1, seed=1, progress=False)
    last = [m for m in model.nets["encoder"].modules() if isinstance(m, torch.nn.Linear)][-1]
    with torch.no_grad():
        last.bias[model.config["latent"]:] = 1e3  # the log-variance half
    q = model.normalise_q(torch.as_tensor(tiny.q[:16], dtype=torch.float32))
    y = model.normalise_y(torch.as_tensor(tiny.y[:16], dtype=torch.float32))
    _, logvar, z = model._encode(q, y, torch.Generator().manual_seed(0))
    assert float(logvar.detach().max()) == LOGVAR_RANGE[1] and torch.isfinite(z).all()
    losses = model._losses(q, y, y, torch.Generator().manual_seed(0))
    assert all(torch.isfinite(v) for v in losses.values())


def test_a_blend_draws_its_share_from_the_partner_and_its_files_are_checked(trained, tmp_path):
    """A model with a blend partner draws each row from the partner with probability ``share``, in torch and in the
    core alike, keeps the partner in its directory, and refuses a partner that is missing, edited or not its own."""
    from manifoldgen.models import open_model
    from manifoldgen.models.files import BLEND_DIR, BlendDecoder

    own, partner = load_model(trained["cvae"][2]), load_model(trained["cfm"][2])
    blend = load_model(trained["cvae"][2])
    blend.blend = (partner, 0.3)
    path = tmp_path / "blend"
    path.mkdir()
    blend.save(path)
    loaded = load_model(path)
    assert loaded.label == "cvae+cfm" and loaded.blend[1] == 0.3 and (path / BLEND_DIR / "model.json").is_file()
    q = loaded.sample([0.3], 4000, torch.Generator().manual_seed(0))
    g = torch.Generator().manual_seed(0)
    taken = (torch.rand(4000, generator=g) < 0.3).numpy()
    expected = np.empty_like(q)
    expected[~taken] = own.sample([0.3], int((~taken).sum()), g)
    expected[taken] = partner.sample([0.3], int(taken.sum()), g)
    np.testing.assert_array_equal(q, expected)
    assert abs(taken.mean() - 0.3) < 0.03
    assert loaded.sample(np.array([[0.3], [0.5], [0.4]]), 3).shape == (3, 7)
    # the core draws the same law: the share from the partner's network, in an order its seed shuffles
    saved = open_model(path)
    decoder = saved.native_decoder()
    assert isinstance(decoder, BlendDecoder) and saved.label == "cvae+cfm"
    assert min(own.row_cost(), partner.row_cost()) < saved.row_cost() < max(own.row_cost(), partner.row_cost())
    rows = decoder.sample(np.array([0.3]), 2000, 7)
    rng = np.random.default_rng(7)
    count = int(rng.binomial(2000, 0.3))
    mine = own.native_decoder().sample(np.array([0.3]), 2000 - count, int(rng.integers(0, 2**63 - 1)))
    theirs = partner.native_decoder().sample(np.array([0.3]), count, int(rng.integers(0, 2**63 - 1)))
    np.testing.assert_array_equal(rows, np.concatenate([mine, theirs])[rng.permutation(2000)])
    # a partner edited, missing, or a blend entry out of range: refused in one line
    doc = json.loads((path / BLEND_DIR / "model.json").read_text())
    doc["refine"] = 9
    doc["sha256"] = document_checksum(doc)
    (path / BLEND_DIR / "model.json").write_text(json.dumps(doc))
    with pytest.raises(ManifoldgenError, match="is not the partner .* names"):
        load_model(path)
    with pytest.raises(ManifoldgenError, match="is not the partner .* names"):
        open_model(path)
    def resealed(edit) -> None:  # the partner's model.json edited, its checksum and the blend entry's made to match
        doc = json.loads((trained["cfm"][2] / "model.json").read_text())
        edit(doc)
        doc["sha256"] = document_checksum(doc)
        (path / BLEND_DIR / "model.json").write_text(json.dumps(doc))
        own = json.loads((path / "model.json").read_text())
        own["blend"]["sha256"] = doc["sha256"]
        own["sha256"] = document_checksum(own)
        (path / "model.json").write_text(json.dumps(own))

    resealed(lambda doc: doc["meta"].update(robot="kinova"))  # the partner's own checks refuse it first
    with pytest.raises(ManifoldgenError, match="blend/model.json: meta 'robot' \"kinova\" contradicts its task"):
        load_model(path)
    resealed(lambda doc: doc.update(blend={"share": 0.5, "sha256": "0" * 64}))
    with pytest.raises(ManifoldgenError, match="blends in a model itself; a blend has one partner"):
        open_model(path)
    shutil.rmtree(path / BLEND_DIR)
    with pytest.raises(ManifoldgenError, match="missing or unreadable; .* copy the whole model directory"):
        load_model(path)
    doc = json.loads((path / "model.json").read_text())
    doc["blend"]["share"] = 1.5
    doc["sha256"] = document_checksum(doc)
    (path / "model.json").write_text(json.dumps(doc))
    with pytest.raises(ManifoldgenError, match=r"'blend' must hold the partner's 'share' of the rows \(a number in"):
        load_model(path)
