"""The ConditionalSampler interface every generative model implements, and its file format.

A model learns ``p(q | y)``. Inputs and outputs are normalised inside the model with the
training split's statistics (saved with it); generated rows are clamped to the joint limits
of the training robot. Files: a directory with ``model.safetensors`` (weights) and
``model.json`` (model name, hyper-parameters, dimensions, normalisation, dataset ``meta``,
SHA-256 of the weights, and ``sha256``: the checksum of every other field of the document, so an
edited number is refused, not silently sampled from). Loading validates everything and never unpickles.
"""

from __future__ import annotations

import hashlib
import json
from abc import ABC, abstractmethod
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

import numpy as np
import safetensors.torch
import torch

from manifoldgen.errors import ManifoldgenError, file_reader
from manifoldgen.models.adam import Adam
from manifoldgen.models.files import (BLEND_DIR, CONFIG_FILE, MODEL_FORMAT_VERSION, NAMED_HYPER, WEIGHTS_FILE,
                                      ModelFacts, blend_decoder, blend_row_cost, check_mix_refine, core_decoder,
                                      decoder_row_cost, document_checksum, read_model_dir)
from manifoldgen.io import atomic_write_bytes, atomic_write_text
from manifoldgen.tasks import Task, task_from_meta
from manifoldgen.training import TrainingLog, check_rows, train
from manifoldgen.models.loss_curve import plot_training

if TYPE_CHECKING:
    from manifoldgen.dataset import Dataset

CHUNK = 10_000  # rows per forward pass when sampling (fastest on 2 CPU cores)
LIMIT_SCALE = 0.01  # rad: a joint-limit overshoot of this size costs as much as one tolerance


def mlp(inputs: int, hidden: list[int], outputs: int, activation: type[torch.nn.Module] = torch.nn.SiLU,
        ) -> torch.nn.Sequential:
    """A plain MLP ``inputs -> hidden... -> outputs`` (no activation on the output)."""
    layers: list[torch.nn.Module] = []
    width = inputs
    for h in hidden:
        layers += [torch.nn.Linear(width, h), activation()]
        width = h
    layers.append(torch.nn.Linear(width, outputs))
    return torch.nn.Sequential(*layers)


def heun_steps(velocity: torch.nn.Module, x: torch.Tensor, y: torch.Tensor, steps: int) -> torch.Tensor:
    """States (B, m) carried from t = 0 to t = 1 - 1/steps by ``dx/dt = velocity([x, y, t])`` at conditions
    y (B, k): ``steps - 1`` Heun steps (the part of :func:`integrate` before its last step)."""
    h = 1.0 / steps
    for i in range(steps - 1):
        u = velocity_at(velocity, x, y, i * h)
        x = x + 0.5 * h * (u + velocity_at(velocity, x + h * u, y, (i + 1) * h))
    return x


def last_step(velocity: torch.nn.Module, x: torch.Tensor, y: torch.Tensor, steps: int) -> torch.Tensor:
    """The final Euler step of :func:`integrate`, from t = 1 - 1/steps to 1: states (B, m)."""
    h = 1.0 / steps
    return x + h * velocity_at(velocity, x, y, 1.0 - h)


def integrate(velocity: torch.nn.Module, x: torch.Tensor, y: torch.Tensor, steps: int) -> torch.Tensor:
    """States (B, m) carried from t = 0 to 1 by ``dx/dt = velocity([x, y, t])`` at conditions y (B, k): ``steps - 1``
    Heun steps, then one Euler step (as the compiled core integrates, ``manifoldgen_core.Decoder``)."""
    return last_step(velocity, heun_steps(velocity, x, y, steps), y, steps)


def velocity_at(velocity: torch.nn.Module, x: torch.Tensor, y: torch.Tensor, t: torch.Tensor | float) -> torch.Tensor:
    """velocity([x, y, t]) (B, m) for states x (B, m), conditions y (B, k), times t ((B, 1) or one for all)."""
    t = t if torch.is_tensor(t) else torch.full((len(x), 1), t)
    return velocity(torch.cat([x, y, t], dim=1))


def _plain_mlp(layers: torch.nn.Sequential) -> bool:
    """Whether ``layers`` are Linear layers with SiLU between them (what the compiled core runs)."""
    kinds = [type(layer) for layer in layers]
    return len(kinds) % 2 == 1 and set(kinds[::2]) == {torch.nn.Linear} and not set(kinds[1::2]) - {torch.nn.SiLU}


def width_for(joints: int) -> int:
    """Hidden-layer width for ``joints`` coordinates: 64 + 8 per joint, rounded up to a multiple of 64
    (7 joints: 128; 14: 192; 34-39: 384)."""
    return 64 * -(-(64 + 8 * int(joints)) // 64)


def pseudo_huber(r2: torch.Tensor) -> torch.Tensor:
    """sqrt(1 + r^2) - 1 for squared normalised residuals: quadratic inside tolerance, linear outside."""
    return torch.sqrt(1.0 + r2) - 1.0


class ConditionalSampler(ModelFacts, ABC):
    """A conditional generative model of configurations ``q (d,)`` given conditions ``y (k,)``.

    Subclasses set ``name`` and ``defaults`` (hyper-parameters, all JSON scalars or lists),
    and implement ``_build``, ``_generate``, ``_optimizers``, ``_train_step`` and
    ``_validation_loss`` on normalised tensors.
    """

    name: ClassVar[str]
    defaults: ClassVar[dict]

    def __init__(self, **hyper):
        unknown = sorted(set(hyper) - set(self.defaults))
        if unknown:
            raise ManifoldgenError(f"unknown hyper-parameter(s) {unknown} for model '{self.name}'; "
                                   f"known: {', '.join(sorted(self.defaults))}")
        self.config: dict = {**self.defaults, **hyper}
        self.given = frozenset(hyper)  # set by the user: never resized (see size_for)
        self.refine: int | None = None  # projection iterations its samples need (training measures it), if known
        self.mix: float | None = None  # share of projected uniform rows its sampler mixes in (the race sets it)
        self.blend: tuple[ConditionalSampler, float] | None = None  # a partner model and its share of the rows
        for key, value in self.config.items():
            _check_hyper(self.name, key, value, self.defaults[key])
        self.meta: dict = {}
        self.d = self.k = 0
        self.norm: dict[str, list[float]] = {}
        self.nets = torch.nn.ModuleDict()
        self.residual_fn: Callable | None = None  # Constraint.penalty, set by training when residual_weight > 0

    # ------------------------------------------------------------------ subclass hooks
    @abstractmethod
    def _build(self) -> None:
        """Create ``self.nets`` for dimensions ``self.d`` and ``self.k``."""

    @abstractmethod
    def _generate(self, y: torch.Tensor, generator: torch.Generator | None) -> torch.Tensor:
        """Normalised conditions (B, k) -> normalised configurations (B, d) (differentiable)."""

    def _sampling_net(self) -> tuple[torch.nn.Sequential, str] | None:
        """The network :meth:`_generate` runs on ``[z, y]`` and its latent law (``"normal"``: N(0, I),
        ``"uniform"``: U(-1, 1)), for :meth:`native_decoder`; None: :meth:`_generate` is something else."""
        return None

    def _prior_net(self) -> tuple[torch.nn.Sequential, int] | None:
        """The velocity field that carries the noise before :meth:`_sampling_net` decodes it, and its integration
        steps (see :func:`integrate`); None: the noise is decoded as drawn."""
        return None

    @abstractmethod
    def _optimizers(self) -> list[Adam]:
        """The optimisers, in a fixed order (their state is checkpointed)."""

    @abstractmethod
    def _train_step(self, q: torch.Tensor, y: torch.Tensor, y_free: torch.Tensor,
                    optimizers: list[Adam], generator: torch.Generator) -> dict[str, float]:
        """One update on a normalised batch; ``y_free`` (B, k) are conditions drawn across the
        trained range for the residual penalty. Returns the losses to log."""

    @abstractmethod
    def _validation_loss(self, q: torch.Tensor, y: torch.Tensor, generator: torch.Generator) -> float:
        """A scalar to early-stop on (lower is better), on the normalised validation split."""

    @classmethod
    def written_before(cls, config: dict) -> dict:
        """The whole ``config`` of a model file written before some hyper-parameters existed: each missing one at
        what that file was trained with (none here; a model that added one says)."""
        return config

    # ------------------------------------------------------------------ setup
    def size_for(self, joints: int, dimension: int, rows: int) -> None:
        """Size what the user did not set from the data: ``latent`` = the manifold's ``dimension``, every hidden
        layer :func:`width_for` ``joints`` wide (a 7-joint arm keeps 128); ``rows``: the training rows."""
        if "latent" in self.config and "latent" not in self.given:
            self.config["latent"] = max(1, int(dimension))
        for key in ("hidden", "critic_hidden"):
            if key in self.config and key not in self.given:
                self.config[key] = [width_for(joints)] * len(self.config[key])

    def setup(self, meta: dict, q: np.ndarray, y: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> None:
        """Record the dataset meta and normalisation (from training rows ``q (N, d)``, ``y (N, k)``)
        and build fresh networks (initialised from the current torch RNG)."""
        self.meta = dict(meta)
        self.d, self.k = q.shape[1], y.shape[1]
        self.norm = {"q_mean": q.mean(0).tolist(), "q_std": np.maximum(q.std(0), 1e-6).tolist(),
                     "y_mean": y.mean(0).tolist(), "y_std": np.maximum(y.std(0), 1e-6).tolist(),
                     "y_low": y.min(0).tolist(), "y_high": y.max(0).tolist(),
                     "lower": np.asarray(lower, float).tolist(), "upper": np.asarray(upper, float).tolist()}
        self._set_tensors()
        self.nets = torch.nn.ModuleDict()
        self._build()

    def _set_tensors(self) -> None:
        t = {key: torch.tensor(v, dtype=torch.float32) for key, v in self.norm.items()
             if key not in ("y_low", "y_high")}
        self._q_mean, self._q_std, self._y_mean, self._y_std = t["q_mean"], t["q_std"], t["y_mean"], t["y_std"]
        self._lower, self._upper = t["lower"], t["upper"]

    def normalise_q(self, q: torch.Tensor) -> torch.Tensor:
        return (q - self._q_mean) / self._q_std

    def normalise_y(self, y: torch.Tensor) -> torch.Tensor:
        return (y - self._y_mean) / self._y_std

    def penalty(self, q: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """Per-row pseudo-Huber constraint residual (B,) (in tolerances) of normalised samples ``q (B, d)`` at
        ``y (B, k)``, plus their joint-limit violation in units of ``LIMIT_SCALE`` rad (so samples learn to stay
        inside). One call for all the rows a step penalises: its cost is mostly per call, not per row."""
        if self.residual_fn is None or self.config.get("residual_weight", 0.0) <= 0:
            return torch.zeros(len(q))
        q = q * self._q_std + self._q_mean
        outside = (torch.relu(q - self._upper) + torch.relu(self._lower - q)) / LIMIT_SCALE
        r2 = self.residual_fn(q, y * self._y_std + self._y_mean) + outside.pow(2).sum(dim=1)
        return pseudo_huber(r2)

    # ------------------------------------------------------------------ public API
    def fit(self, dataset: Dataset, *, epochs: int | None = None, seed: int = 0, progress: bool = True,
            out: str | Path | None = None, resume: bool = False, task: Task | None = None) -> TrainingLog:
        """Train on ``dataset`` (see :func:`manifoldgen.training.train`) for ``task`` (see :func:`dataset_task`);
        with ``out``, checkpoints are written there every epoch, and the final model and its loss curves
        (``loss.png``) are saved there."""
        log = train(self, dataset, task=dataset_task(dataset, task), epochs=epochs, seed=seed, progress=progress,
                    out=out, resume=resume)
        if out is not None:
            plot_training(log, Path(out) / "loss.png")
        return log

    def sample(self, y: np.ndarray, n: int, generator: torch.Generator | None = None) -> np.ndarray:
        """(n, d) float64 configurations for condition ``y`` ((k,), (1, k) or (n, k))."""
        if not self.nets:
            raise ManifoldgenError(f"model '{self.name}' is not trained; call fit() or load one")
        if n < 0:
            raise ManifoldgenError(f"number of samples must be >= 0, got {n}")
        given = np.asarray(y, dtype=float)
        if given.ndim > 2 or (given.ndim == 2 and given.shape[1] != self.k) or given.size % self.k:
            raise ManifoldgenError(f"y must hold conditions of {self.k} value(s) each, as (k,), (1, k) or (n, k) with "
                                   f"k = {self.k}; got shape {given.shape}")
        given = given.reshape(-1, self.k)
        bad = ~(np.abs(given) < 1e30).all(axis=1)  # NaN, infinite, or lost in float32
        if bad.any():
            raise ManifoldgenError(f"condition y must be finite numbers of sensible size, got {given[bad][0].tolist()}")
        if len(given) not in (1, n):
            raise ManifoldgenError(f"y must have 1 or n={n} rows, got {len(given)}")
        if self.blend is None:
            return self._sample_own(given, n, generator)
        partner, share = self.blend
        taken = (torch.rand(n, generator=generator) < share).numpy()
        out = np.empty((n, self.d), dtype=np.float64)
        for rows, model in ((~taken, self), (taken, partner)):
            at = given if len(given) == 1 else given[rows]
            out[rows] = model._sample_own(at, int(rows.sum()), generator)
        return out

    def _sample_own(self, given: np.ndarray, n: int, generator: torch.Generator | None) -> np.ndarray:
        """(n, d) rows of this model's own network (not its blend partner's) at checked conditions (1 or n, k)."""
        out = np.empty((n, self.d), dtype=np.float64)
        yt = self.normalise_y(torch.from_numpy(given.astype(np.float32)))
        if self.nets.training:
            self.nets.eval()
        with torch.inference_mode():
            for start in range(0, n, CHUNK):
                stop = min(n, start + CHUNK)
                yc = yt.expand(stop - start, self.k) if len(yt) == 1 else yt[start:stop]
                out[start:stop] = (self._generate(yc, generator) * self._q_std + self._q_mean).numpy()
        return np.clip(out, self.norm["lower"], self.norm["upper"], out=out)

    def decoder_spec(self) -> dict | None:
        """model.json's ``decoder`` entry (see :mod:`manifoldgen.models.files`): the sampling network's name,
        noise law and width, integration steps and Linear layer count, and its prior's (name, steps, layers) where
        the noise passes one; None where either is not Linear layers with SiLU between them (then only torch
        samples it)."""
        net = self._sampling_net()
        if net is None or not self.nets:
            return None
        layers, law = net
        prior = self._prior_net()
        if not _plain_mlp(layers) or (prior is not None and not _plain_mlp(prior[0])):
            return None
        steps = self._integration_steps()
        spec = {"net": self._net_name(layers), "law": law, "noise": self.d if steps else int(self.config["latent"]),
                "steps": steps, "layers": len(layers[::2])}
        if prior is not None:
            spec["prior"] = {"net": self._net_name(prior[0]), "steps": prior[1], "layers": len(prior[0][::2])}
        return spec

    def _net_name(self, module: torch.nn.Module) -> str:
        return next(key for key, net in self.nets.items() if net is module)

    def native_decoder(self):
        """The sampling network copied into the compiled core (``manifoldgen_core.Decoder``: ``sample(y (k,),
        count, seed) -> (count, d)``, the same law as :meth:`sample`, float32 as torch, its own random stream),
        or None where the core is not built or :meth:`decoder_spec` is None."""
        spec = self.decoder_spec()
        if spec is None:
            return None
        weights = {key: value.float().numpy() for key, value in self.state_tensors().items()}
        return blend_decoder(core_decoder(spec, weights, self.d, self.norm), self.blend)

    def row_cost(self) -> int | None:
        """Multiply-adds to sample one row (:func:`~manifoldgen.models.files.decoder_row_cost`), or None where
        :meth:`decoder_spec` is None."""
        spec = self.decoder_spec()
        return blend_row_cost(decoder_row_cost(spec, self.nets.state_dict()) if spec else None, self.blend)

    def _integration_steps(self) -> int:
        """0: the sampling network maps [latent, y] to a row; n > 0: it is a velocity field v([x, y, t]) that
        sampling integrates from latent rows in n Heun steps (a flow-matching model)."""
        return 0

    def state_tensors(self) -> dict[str, torch.Tensor]:
        return {k: v.detach().contiguous().clone() for k, v in self.nets.state_dict().items()}

    def describe(self) -> dict:
        """The JSON document saved as model.json (without the weights' hash)."""
        return {"format_version": MODEL_FORMAT_VERSION, "model": self.name, "config": self.config,
                "dims": {"d": self.d, "k": self.k}, "normalisation": self.norm, "meta": self.meta,
                **({"refine": self.refine} if self.refine is not None else {}),
                **({"mix": self.mix} if self.mix is not None else {}),
                **({"decoder": spec} if (spec := self.decoder_spec()) else {})}

    def save(self, path: str | Path) -> None:
        """Write ``path/model.safetensors`` and ``path/model.json`` (atomically, weights first; a blend partner
        first of all, into ``path/blend``)."""
        if not self.nets:
            raise ManifoldgenError(f"model '{self.name}' is not trained; nothing to save")
        path = Path(path)
        blend = {}
        if self.blend is not None:
            partner, share = self.blend
            (path / BLEND_DIR).mkdir(exist_ok=True)
            partner.save(path / BLEND_DIR)
            said = json.loads((path / BLEND_DIR / CONFIG_FILE).read_text())["sha256"]
            blend = {"blend": {"share": float(share), "sha256": said}}
        blob = safetensors.torch.save(self.state_tensors())
        atomic_write_bytes(path / WEIGHTS_FILE, blob)
        doc = {**self.describe(), **blend, "weights_sha256": hashlib.sha256(blob).hexdigest()}
        doc["sha256"] = document_checksum(doc)
        atomic_write_text(path / CONFIG_FILE, json.dumps(doc, indent=1))

    @classmethod
    @file_reader
    def load(cls, path: str | Path) -> ConditionalSampler:
        """Load a model directory written by :meth:`save` (validated; clear errors)."""
        doc, tensors = read_model_dir(path)
        if doc["model"] != cls.name or "blend" in doc:
            raise ManifoldgenError(f"{path} holds a '{doc['model']}' model{' blended with another' * ('blend' in doc)}"
                                   f", not a '{cls.name}' alone; use manifoldgen.models.load_model")
        return cls.from_files(path, doc, tensors)

    @classmethod
    def from_files(cls, path: str | Path, doc: dict, tensors: dict[str, np.ndarray]) -> ConditionalSampler:
        """Build from a validated model.json document and its weights."""
        try:
            model = cls(**cls.written_before(doc["config"]))
        except (ManifoldgenError, TypeError) as exc:
            raise ManifoldgenError(f"{path}/{CONFIG_FILE} has an invalid config ({exc}); "
                                   "the file was edited or is damaged: retrain or restore it") from exc
        model.meta, model.norm = doc["meta"], doc["normalisation"]
        model.refine, model.mix = check_mix_refine(path, doc)
        model.d, model.k = doc["dims"]["d"], doc["dims"]["k"]
        model._set_tensors()
        try:
            model._build()
            model.nets.load_state_dict({k: torch.from_numpy(v) for k, v in tensors.items()}, strict=True)
            model.nets.eval()
        except (RuntimeError, ValueError, TypeError) as exc:
            first = str(exc).strip().splitlines()[0][:200]
            raise ManifoldgenError(f"{path}: weights do not match the architecture in {CONFIG_FILE} ({first}); "
                                   "the config was edited or the files come from different models") from exc
        return model


def dataset_task(dataset: Dataset, task: Task | None = None) -> Task:
    """The task a model learns ``dataset`` for, once its rows pass the checks that need none
    (:func:`~manifoldgen.training.check_rows`): ``task`` (refused unless the dataset was made for it; needed
    when the dataset's meta names a user's constraint type), by default the task rebuilt from the meta."""
    check_rows(dataset)
    return task_from_meta(dataset.meta, task=task, what="the dataset")


MAX_LR = 10.0  # a learning rate above it only diverges
MAX_WEIGHT = 1e6  # a loss weight (beta, residual weights, fractions) above it overflows the float32 losses
MAY_BE_ZERO = ("prior_steps",)  # whole-number hyper-parameters where 0 turns a part off (the CVAE's learned prior)


def _check_hyper(model: str, key: str, value, default) -> None:
    """Refuse a hyper-parameter value no model can train with (raw torch errors otherwise)."""
    if isinstance(default, list):
        ok = isinstance(value, list) and value and all(isinstance(v, int) and not isinstance(v, bool) and v >= 1
                                                       for v in value)
        need = "a non-empty list of positive integers"
    elif isinstance(default, int) and not isinstance(default, bool):
        low = 0 if key in MAY_BE_ZERO else 1
        ok = isinstance(value, int) and not isinstance(value, bool) and value >= low
        need = "a whole number >= 0" if low == 0 else "a positive integer"
    elif isinstance(default, float):
        number = isinstance(value, (int, float)) and not isinstance(value, bool) and bool(np.isfinite(value))
        if key == "lr":
            ok, need = number and 0 < value <= MAX_LR, f"a number in (0, {MAX_LR:g}]"
        elif key == "beta1":
            ok, need = number and 0 <= value < 1, "a number in [0, 1)"
        else:  # a loss weight: larger ones overflow the float32 losses
            ok, need = number and 0 <= value <= MAX_WEIGHT, f"a number from 0 to {MAX_WEIGHT:g}"
    elif key in NAMED_HYPER:
        ok, need = value in NAMED_HYPER[key], " or ".join(NAMED_HYPER[key])
    else:
        return
    if not ok:
        raise ManifoldgenError(f"hyper-parameter {key}={value!r} of model '{model}' must be {need} "
                               f"(default {default!r})")


class SingleLossSampler(ConditionalSampler):
    """A model trained by one optimiser on one loss: ``_losses(...)["loss"]`` (the CVAE, the flow)."""

    @abstractmethod
    def _losses(self, q: torch.Tensor, y: torch.Tensor, y_free: torch.Tensor,
                generator: torch.Generator) -> dict[str, torch.Tensor]:
        """The losses on a normalised batch; ``"loss"`` is minimised, the others are logged."""

    def _train_step(self, q, y, y_free, optimizers, generator):
        """One update, skipped when the loss or a gradient is not finite (a NaN would poison the optimiser's
        moments for good); ``skipped`` (0 or 1) says which."""
        self.nets.train()
        losses = self._losses(q, y, y_free, generator)
        optimizers[0].zero_grad()
        finite = bool(torch.isfinite(losses["loss"]))
        if finite:
            losses["loss"].backward()
            grads = [p.grad.reshape(-1) for p in self.nets.parameters() if p.grad is not None]
            finite = bool(torch.isfinite(torch.cat(grads)).all()) if grads else True
        if finite:
            optimizers[0].step()
        return {**{key: float(v.detach()) for key, v in losses.items()}, "skipped": float(not finite)}

    def _validation_loss(self, q, y, generator):
        self.nets.eval()
        with torch.no_grad():
            return float(self._losses(q, y, y, generator)["loss"])
