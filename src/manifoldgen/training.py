"""Training loop for every ConditionalSampler: split, early stopping, checkpoints, resume.

``train(model, dataset, task=t, seed=s)`` is deterministic for a seed: the split, the initial
weights, the batch order and every noise draw come from generators seeded with ``s``.
With ``out``, a checkpoint (weights, optimiser state, generator state, history, best
weights: one safetensors file whose header carries the JSON state) is written atomically after
every epoch, so an interrupted run continued with
``resume=True`` ends exactly where the uninterrupted run would have. When training ends the
best-validation weights are saved to ``out`` with ``training.json`` (a model's ``fit`` adds ``loss.png``).

Training takes the model and the task by their interfaces (:class:`Trainable`, :class:`TaskLike`): the models
import this module, and the caller gives the task the dataset was made for.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
import warnings
from dataclasses import asdict, dataclass, field
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np
import safetensors.torch
import torch

from manifoldgen.dataset import Dataset, check_meta
from manifoldgen.errors import ManifoldgenError, differences, listed, short
from manifoldgen.io import atomic_write_bytes, atomic_write_text, locks_output
from manifoldgen.progress import progress_bar
from manifoldgen.provenance import check_task_copies
from manifoldgen.runtime import REFINE, check_seed

if TYPE_CHECKING:
    from manifoldgen.constraints import Condition, Constraint
    from manifoldgen.robot import Robot

CHECKPOINT = "checkpoint.safetensors"  # one file: a kill leaves the previous epoch's or this one's, never a mix
OUTPUT_FILES = ("model.safetensors", "model.json", "training.json", "loss.png", CHECKPOINT)
MIN_ROWS = 10
MAX_MODEL_BYTES = 4 * 2**30  # training memory a model's layers may take (float32 weights, gradients, Adam's two)
VALIDATION = 0.1  # the share of a dataset's rows training holds out (early stopping; the default model's choice)
CHECKED_ROWS = 256  # dataset rows rechecked against the task before training
REFINE_LADDER = (REFINE, 5, 10, 20)  # projection iterations tried for a model's samples (see needed_refine)
REFINE_SHARE = 0.95  # ... until this share of what the last rung brings within tolerance is
REFINE_CONDITIONS, REFINE_SAMPLES = 4, 256  # condition values and samples at each it is measured on
DIMENSION_ROWS = 16  # dataset rows whose constraint Jacobian gives the manifold's dimension (the largest rank wins)


class Trainable(Protocol):
    """What training drives: a :class:`~manifoldgen.models.base.ConditionalSampler`, by its interface."""

    name: str
    config: dict
    k: int
    nets: torch.nn.ModuleDict
    refine: int | None
    residual_fn: Callable | None

    def size_for(self, joints: int, dimension: int, rows: int) -> None: ...
    def setup(self, meta: dict, q: np.ndarray, y: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> None: ...
    def normalise_q(self, q: torch.Tensor) -> torch.Tensor: ...
    def normalise_y(self, y: torch.Tensor) -> torch.Tensor: ...
    def state_tensors(self) -> dict[str, torch.Tensor]: ...
    def sample(self, y: np.ndarray, n: int, generator: torch.Generator | None = None) -> np.ndarray: ...
    def save(self, path: str | Path) -> None: ...
    def _optimizers(self) -> list: ...  # optimisers: zero_grad(), step(), state_dict(), load_state_dict()
    def _train_step(self, q: torch.Tensor, y: torch.Tensor, y_free: torch.Tensor,
                    optimizers: list, generator: torch.Generator) -> dict[str, float]: ...
    def _validation_loss(self, q: torch.Tensor, y: torch.Tensor, generator: torch.Generator) -> float: ...


class TaskLike(Protocol):
    """What training reads of a :class:`~manifoldgen.tasks.Task`."""

    robot: Robot
    constraint: Constraint

    @property
    def condition(self) -> Condition: ...


@dataclass
class TrainingLog:
    """What happened: per-epoch mean training losses and validation score."""

    model: str
    seed: int
    epochs: int  # the requested maximum
    history: list[dict] = field(default_factory=list)  # {"epoch", "train": {name: mean}, "val", "seconds"}
    best_epoch: int = 0
    best_val: float = float("inf")
    stopped_early: bool = False
    resumed_at: int | None = None
    diverged_at: int | None = None  # the epoch whose validation score was not finite (training stopped there)

    @property
    def seconds(self) -> float:
        return float(sum(h["seconds"] for h in self.history))

    def to_dict(self) -> dict:
        return {**asdict(self), "seconds": self.seconds}


def check_rows(dataset: Dataset) -> None:
    """Refuse datasets a conditional model cannot learn from, whatever their task: inconsistent shapes, NaN,
    too few rows, a single condition value."""
    q, y = np.asarray(dataset.q), np.asarray(dataset.y)
    if q.ndim != 2 or y.ndim != 2 or len(q) != len(y):
        raise ManifoldgenError(f"dataset has inconsistent shapes q {q.shape}, y {y.shape}")
    if not (np.isfinite(q).all() and np.isfinite(y).all()):
        raise ManifoldgenError("dataset contains NaN or infinite values; recollect it or drop those rows")
    if len(q) < MIN_ROWS:
        raise ManifoldgenError(f"dataset has only {len(q)} rows; a model needs at least {MIN_ROWS}")
    if not y.shape[1]:
        raise ManifoldgenError("dataset has no condition (its task is unconditioned); a conditional model needs one: "
                               "give the task's constraint a conditioned value (see docs/tasks.md), or plan with the "
                               "projection sampler")
    if len(np.unique(y, axis=0)) < 2:
        raise ManifoldgenError(f"dataset has a single condition value {y[0].tolist()}; a conditional model "
                               "needs rows at two or more values (collect with several --condition values)")


def check_dataset(dataset: Dataset, task: TaskLike) -> None:
    """:func:`check_rows`, then refuse a dataset that does not hold ``task`` (the task it was made for): joint
    order, condition columns, rows on the constraint."""
    check_rows(dataset)
    q, y = np.asarray(dataset.q), np.asarray(dataset.y)
    if list(dataset.meta["joints"]) != task.robot.joints:
        raise ManifoldgenError(f"dataset joints {dataset.meta['joints']} are not its task's planning group "
                               f"{task.robot.joints} in that order; recollect the dataset")
    if y.shape[1] != task.condition.k:
        raise ManifoldgenError(f"dataset has {y.shape[1]} condition columns but its task has {task.condition.k} "
                               f"({', '.join(task.condition.names)}); recollect the dataset")
    check_meta(dataset.meta, y.shape[1], "dataset")
    check_task_copies(dataset.meta, task.constraint, "dataset")
    rows = np.random.default_rng(0).choice(len(q), min(len(q), CHECKED_ROWS), replace=False)
    bad = rows[~task.constraint.satisfied(q[rows], y[rows])]
    if len(bad):
        i = int(bad[0])
        raise ManifoldgenError(f"dataset row {i} does not satisfy its task's constraint "
                               f"({_why_off(task, q[i], y[i])}); {len(bad)} of {len(rows)} rows checked fail: "
                               "recollect the dataset")


def _why_off(task: TaskLike, q: np.ndarray, y: np.ndarray) -> str:
    """Why the row ``q (n,)`` at ``y (k,)`` does not satisfy ``task``'s constraint: the joint limit it leaves, its
    residual beyond tolerance, or an inequality it breaks."""
    robot = task.robot
    past = np.maximum(robot.lower - q, q - robot.upper)
    j = int(np.argmax(past))
    if not robot.within_limits(q)[0]:
        return f"joint {robot.joints[j]} is {past[j]:.3g} outside its limits [{robot.lower[j]:g}, {robot.upper[j]:g}]"
    violation = float(task.constraint.violation(q, y)[0])
    if violation > 1.0:
        return f"worst residual {violation:.3g} x tolerance"
    return "it breaks an inequality of the constraint"


def needed_refine(model: Trainable, task: TaskLike, y: np.ndarray, seed: int) -> int:
    """The fewest projection iterations of :data:`REFINE_LADDER` that bring within tolerance :data:`REFINE_SHARE`
    of the model's samples that the ladder's top brings, at the condition values of ``y (N, k)`` (at most
    :data:`REFINE_CONDITIONS` of them): what a model sampler refines its rows by default. (Rows no projection
    saves, outside the limits or the inequalities, do not push it to the top.)"""
    from manifoldgen.constraints import project

    values = np.unique(y, axis=0)
    values = values[np.unique(np.linspace(0, len(values) - 1, min(len(values), REFINE_CONDITIONS)).astype(int))]
    with torch.no_grad():
        rows = [(model.sample(v, REFINE_SAMPLES, torch.Generator().manual_seed(seed + i)), v)
                for i, v in enumerate(values)]
    within = [np.mean([task.constraint.satisfied(project(task.constraint, q, v, max_iters=refine).q, v).mean()
                       for q, v in rows]) for refine in REFINE_LADDER]
    return next(refine for refine, rate in zip(REFINE_LADDER, within) if rate >= REFINE_SHARE * within[-1])


def split(rows: int, validation: float, generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """(validation indices, training indices) of ``rows`` rows: a ``validation`` fraction (at least one) held
    out, drawn from ``generator`` (a fresh one seeded with the training seed gives :func:`train`'s split)."""
    perm = torch.randperm(rows, generator=generator)
    n_val = max(1, int(round(validation * rows)))
    return perm[:n_val], perm[n_val:]


def fingerprint(dataset: Dataset) -> str:
    """A short digest of the dataset's rows (q and y): what a training run records as its data."""
    digest = hashlib.sha256(np.ascontiguousarray(dataset.q, dtype=np.float64).tobytes())
    digest.update(np.ascontiguousarray(dataset.y, dtype=np.float64).tobytes())
    return digest.hexdigest()[:16]


def manifold_dimension(task: TaskLike, q: np.ndarray, y: np.ndarray) -> int:
    """Dimension of ``task``'s constraint manifold at rows q (B, n), y (B, k): n minus the largest rank of the
    constraint's Jacobian over the rows (the equalities' rank; 1e-6 tolerance)."""
    _, J = task.constraint.jacobian(np.asarray(q, float), np.asarray(y, float))
    return task.robot.n - max(int(np.linalg.matrix_rank(j, tol=1e-6)) for j in J)


def _check_size(model: Trainable, width: int) -> None:
    """Refuse, before anything is allocated, hidden layers whose weights, gradients and optimiser state would take
    more than :data:`MAX_MODEL_BYTES` (float32; ``width``: joints + condition values (+ the latent size), about a
    layer's in or out)."""
    layers = [v for k, v in model.config.items() if k.endswith("hidden") and isinstance(v, list)]
    width += model.config.get("latent", 0) if isinstance(model.config.get("latent"), int) else 0
    parameters = sum(sum(a * b for a, b in zip([width, *widths], [*widths, width])) for widths in layers)
    if 4 * 4 * parameters > MAX_MODEL_BYTES:
        latent = f" and latent {model.config['latent']}" if "latent" in model.config else ""
        raise ManifoldgenError(f"hidden layers {layers}{latent} make about {parameters:,} parameters, "
                               f"{16 * parameters / 2**30:.1f} "
                               f"GiB to train (weights, gradients, optimiser state); keep it under "
                               f"{MAX_MODEL_BYTES / 2**30:.0f} GiB (e.g. --set 'hidden=[256,256]')")


def _check_latent(model: Trainable, dimension: int) -> None:
    """Warn when the model's latent is smaller than the manifold's ``dimension``: its samples then cover at
    most a latent-dimensional sheet of the manifold."""
    latent = model.config.get("latent")
    if latent is not None and int(latent) < dimension:
        warnings.warn(f"{model.name} latent {latent} is below the constraint manifold's dimension {dimension} "
                      f"(joints minus the constraint Jacobian's rank): its samples cover at most a {latent}-"
                      f"dimensional sheet of it; train with --set latent={dimension}", stacklevel=3)


def learning_rate_share(schedule: str, step: int, steps: int) -> float:
    """The share of its ``lr`` a model trains with at ``step`` of ``steps``: 1 throughout (``constant``), or from 1
    down to 0 along half a cosine (``cosine``: large steps early, small ones to settle); a model's
    ``lr_schedule``, one of :data:`~manifoldgen.models.files.NAMED_HYPER`."""
    return 1.0 if schedule == "constant" else 0.5 * (1.0 + math.cos(math.pi * step / steps))


@locks_output("out")  # one training per model directory
def train(model: Trainable, dataset: Dataset, *, task: TaskLike, epochs: int | None = None, seed: int = 0,
          progress: bool = True, out: str | Path | None = None, resume: bool = False,
          validation: float = VALIDATION) -> TrainingLog:
    """Fit ``model`` on ``dataset`` with a held-out ``validation`` fraction and early stopping; ``task``: the
    task the dataset was made for (the caller's to find, see :func:`manifoldgen.models.base.dataset_task`;
    checked here with :func:`check_dataset`)."""
    check_dataset(dataset, task)
    if epochs is not None and int(epochs) <= 0:
        raise ManifoldgenError(f"--epochs must be positive, got {epochs}")
    seed = check_seed(seed)
    out = Path(out) if out is not None else None
    if out is not None:
        if out.exists() and not out.is_dir():
            raise ManifoldgenError(f"{out} exists and is not a directory; choose a model directory path")
        if not out.parent.exists():
            raise ManifoldgenError(f"output directory {out.parent} does not exist; create it first")
        has_checkpoint = (out / CHECKPOINT).exists()
        if resume and not has_checkpoint:
            raise ManifoldgenError(f"no checkpoint in {out} to resume (training finished or never started); "
                                   "run without --resume")
        if has_checkpoint and not resume:
            raise ManifoldgenError(f"{out} holds a checkpoint of an interrupted run; pass --resume to continue "
                                   "it, or choose another directory")
        finished = not has_checkpoint and (out / "model.json").exists()
        check_unused(out)
    elif resume:
        raise ManifoldgenError("resume needs the output directory of the interrupted run")

    q_all = torch.as_tensor(dataset.q, dtype=torch.float32)
    y_all = torch.as_tensor(dataset.y, dtype=torch.float32)
    gen = torch.Generator().manual_seed(seed)
    val_idx, train_idx = split(len(q_all), validation, gen)
    dimension = manifold_dimension(task, dataset.q[:DIMENSION_ROWS], dataset.y[:DIMENSION_ROWS])
    model.size_for(task.robot.n, dimension, len(train_idx))  # the same data gives a resumed run the same sizes
    epochs = int(model.config["epochs"] if epochs is None else epochs)
    _check_size(model, task.robot.n + task.condition.k)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model.setup(dataset.meta, dataset.q[train_idx.numpy()], dataset.y[train_idx.numpy()],
                    task.robot.lower, task.robot.upper)
    model.residual_fn = task.constraint.penalty if model.config.get("residual_weight", 0.0) > 0 else None
    _check_latent(model, dimension)
    q_train, y_train = model.normalise_q(q_all[train_idx]), model.normalise_y(y_all[train_idx])
    q_val, y_val = model.normalise_q(q_all[val_idx]), model.normalise_y(y_all[val_idx])
    y_low, y_high = y_train.min(0).values, y_train.max(0).values
    optimizers = model._optimizers()
    base_rates = [optimizer.lr for optimizer in optimizers]  # a resumed optimiser's state holds a decayed one
    schedule = model.config.get("lr_schedule", "constant")
    log = TrainingLog(model.name, seed, epochs)
    best_state, bad = model.state_tensors(), 0
    identity = {"model": model.name, "config": model.config, "seed": seed, "epochs": epochs,
                "dataset": fingerprint(dataset), "validation": validation}
    if resume:
        best_state, bad = _load_checkpoint(out, identity, model, optimizers, gen, log)
    elif out is not None and finished:
        _check_finished(out, identity)

    batch = int(model.config["batch"])
    steps = max(1, len(q_train) // batch)
    start_epoch = len(log.history)
    try:
        with progress_bar(f"{model.name}", total=(epochs - start_epoch) * steps, enabled=progress) as bar:
            for epoch in range(start_epoch, epochs):
                if bad >= int(model.config["patience"]):
                    log.stopped_early = True
                    break
                tic = time.perf_counter()
                order = torch.randperm(len(q_train), generator=gen)
                sums: dict[str, float] = {}
                for s in range(steps):
                    idx = order[s * batch:(s + 1) * batch]
                    y_free = y_low + (y_high - y_low) * torch.rand(len(idx), model.k, generator=gen)
                    share = learning_rate_share(schedule, epoch * steps + s, epochs * steps)
                    for optimizer, rate in zip(optimizers, base_rates):
                        optimizer.lr = rate * share
                    losses = model._train_step(q_train[idx], y_train[idx], y_free, optimizers, gen)
                    for key, value in losses.items():
                        sums[key] = sums.get(key, 0.0) + value
                    bar.advance(1)
                    if s % 20 == 0:
                        bar.describe(f"{model.name} epoch {epoch + 1}/{epochs} "
                                     + " ".join(f"{k} {v:.3g}" for k, v in losses.items())
                                     + f" | val {log.best_val:.4g}")
                val = model._validation_loss(q_val, y_val, torch.Generator().manual_seed(seed + epoch))
                if not np.isfinite(val):
                    if not log.best_epoch:
                        raise ManifoldgenError(f"training diverged at epoch {epoch + 1} (validation loss {val}); lower "
                                               "the learning rate (lr) or the loss weights you set, or try another seed")
                    log.diverged_at, log.stopped_early = epoch + 1, True  # the best epoch before it is kept
                    break
                log.history.append({"epoch": epoch + 1, "train": {k: v / steps for k, v in sums.items()},
                                    "val": val, "seconds": time.perf_counter() - tic})
                if val < log.best_val:
                    log.best_val, log.best_epoch, best_state, bad = val, epoch + 1, model.state_tensors(), 0
                else:
                    bad += 1
                if out is not None:
                    _save_checkpoint(out, identity, model, optimizers, gen, log, best_state, bad)
            else:
                log.stopped_early = bad >= int(model.config["patience"])
    except KeyboardInterrupt:
        if out is None:
            raise
        raise ManifoldgenError(f"training interrupted after epoch {len(log.history)}; the checkpoint is in "
                               f"{out}: rerun the same command with --resume to continue") from None

    model.nets.load_state_dict(best_state)
    model.refine = needed_refine(model, task, dataset.y[val_idx.numpy()], seed)
    if out is not None:
        model.save(out)
        atomic_write_text(out / "training.json", json.dumps({**log.to_dict(), "identity": identity}, indent=1))
        (out / CHECKPOINT).unlink(missing_ok=True)
    return log


def check_unused(out: Path, marks: tuple[str, ...] = ("model.json", CHECKPOINT)) -> None:
    """Refuse a folder ``out`` that holds files but none of ``marks`` (the entries of a model directory, finished or
    being trained): they are not a run's to replace (training.json, loss.png ...). Temporary files a killed writer
    left do not count."""
    if not out.is_dir() or any((out / mark).exists() for mark in marks):
        return
    leftovers = tuple(f".{name}." for name in OUTPUT_FILES)  # the start of a killed writer's temporary file
    found = sorted(entry.name for entry in out.iterdir()
                   if not (entry.name.startswith(leftovers) and entry.name.endswith(".tmp")))
    if found:
        raise ManifoldgenError(f"{out} holds {listed(found, ', ')} but no {' nor '.join(marks)}, so it is not a model "
                               "directory; train into a new or empty folder (-o)")


def _check_finished(out: Path, identity: dict) -> None:
    """Refuse to replace the finished model in ``out`` unless its ``training.json`` records this run's
    ``identity`` (model, config, seed, epochs, dataset, validation share): training it again gives the same files."""
    try:
        made = json.loads((out / "training.json").read_text()).get("identity")
    except (OSError, ValueError, AttributeError):
        made = None
    if made is None:
        raise ManifoldgenError(f"{out} holds a finished model whose settings are not recorded (training.json); "
                               "choose another directory (-o), or delete it to train anew")
    changed = differences(made, identity)
    if changed:
        raise ManifoldgenError(f"{out} holds a finished model made with other settings ({changed}); choose another "
                               "directory (-o), or delete it to train anew")


# ---------------------------------------------------------------------- checkpoints
def _save_checkpoint(out: Path, identity: dict, model: Trainable, optimizers: list,
                     gen: torch.Generator, log: TrainingLog, best_state: dict, bad: int) -> None:
    tensors = {f"model.{k}": v for k, v in model.state_tensors().items()}
    tensors |= {f"best.{k}": v for k, v in best_state.items()}
    tensors["rng"] = gen.get_state()
    optim_doc = []
    for j, opt in enumerate(optimizers):
        sd = opt.state_dict()
        scalars: dict[str, dict] = {}
        for pid, state in sd["state"].items():
            for key, value in state.items():
                if torch.is_tensor(value):
                    tensors[f"opt{j}.{pid}.{key}"] = value.detach().contiguous().clone()
                else:
                    scalars.setdefault(str(pid), {})[key] = value
        optim_doc.append({"param_groups": sd["param_groups"], "scalars": scalars,
                          "tensor_keys": {str(pid): [k for k, v in st.items() if torch.is_tensor(v)]
                                          for pid, st in sd["state"].items()}})
    doc = {"identity": identity, "log": asdict(log), "bad": bad, "optimizers": optim_doc}
    atomic_write_bytes(out / CHECKPOINT, safetensors.torch.save(tensors, metadata={"state": json.dumps(doc)}))


def _load_checkpoint(out: Path, identity: dict, model: Trainable, optimizers: list,
                     gen: torch.Generator, log: TrainingLog) -> tuple[dict, int]:
    damaged = (f"the checkpoint {out / CHECKPOINT} is damaged ({{}}); delete it and train from scratch, "
               "or choose another directory")
    try:
        blob = (out / CHECKPOINT).read_bytes()
        size = int.from_bytes(blob[:8], "little")  # safetensors: header length, JSON header, tensor data
        doc = json.loads(json.loads(blob[8:8 + size])["__metadata__"]["state"])
        tensors = safetensors.torch.load(blob)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ManifoldgenError(damaged.format(f"{type(exc).__name__}: {exc}")) from None
    except Exception as exc:  # safetensors raises its own error types for damaged files
        raise ManifoldgenError(damaged.format(type(exc).__name__)) from None
    changed = differences(doc.get("identity"), identity)
    if changed:
        raise ManifoldgenError(f"the checkpoint in {out} was made with another dataset, model, seed or settings "
                               f"({changed}); resume with the same command, or choose another directory")
    try:  # the identity matched: the contents must be what _save_checkpoint writes
        model.nets.load_state_dict({k[6:]: v for k, v in tensors.items() if k.startswith("model.")})
        best = {k[5:]: v for k, v in tensors.items() if k.startswith("best.")}
        for j, (opt, od) in enumerate(zip(optimizers, doc["optimizers"], strict=True)):
            state = {}
            for pid, keys in od["tensor_keys"].items():
                state[int(pid)] = {key: tensors[f"opt{j}.{pid}.{key}"] for key in keys}
                state[int(pid)].update(od["scalars"].get(pid, {}))
            opt.load_state_dict({"state": state, "param_groups": od["param_groups"]})
        gen.set_state(tensors["rng"])
        saved = doc["log"]
        log.history, log.best_epoch, log.best_val = list(saved["history"]), saved["best_epoch"], saved["best_val"]
        bad = int(doc["bad"])
    except (KeyError, TypeError, ValueError, RuntimeError, IndexError, AttributeError) as exc:
        raise ManifoldgenError(damaged.format(f"{type(exc).__name__}: {short(str(exc), 60)}")) from None
    log.resumed_at = len(log.history)
    return best, bad
