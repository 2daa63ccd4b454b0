"""Model sweeps: models x latent sizes x seeds trained on one dataset and ranked on held-out rows
(``manifoldgen sweep DATASET``).

Each candidate is trained as ``manifoldgen train DATASET --model MODEL --set latent=LATENT --seed SEED`` would
(a model without a latent, such as ``cfm`` or ``flow``, once per seed at its own size; no latent given: the size
from the data) and scored on the rows its training held out (:func:`manifoldgen.selection.score`: ``accuracy``,
the share of raw samples within tolerance, and ``recall``, the share of held-out rows some sample comes near).
The ranking is the default model's rule: the candidates within :data:`~manifoldgen.selection.RECALL_SLACK` of the
best recall first, most accurate first; then the others, by recall. The best is written as the model directory
``OUT``, every candidate under ``OUT/candidates/NAME``, and the table of all in ``OUT/sweep.json``, rewritten as
each candidate finishes: rerunning the same command resumes (other settings are refused). With a cluster each
candidate is a task: a worker trains it in a temporary folder and returns its files, which the driver writes.
"""

from __future__ import annotations

import hashlib
import json
import tempfile
import warnings
from pathlib import Path

import numpy as np
import torch

from manifoldgen.cluster import Cluster, connect
from manifoldgen.dataset import Dataset
from manifoldgen.errors import ManifoldgenError, differences, short
from manifoldgen.io import atomic_write_bytes, atomic_write_text, check_name
from manifoldgen.models import MODELS, get_model_class, load_model
from manifoldgen.models.base import dataset_task
from manifoldgen.progress import progress_bar
from manifoldgen.runtime import check_seed, set_threads
from manifoldgen.selection import RECALL_SLACK, score
from manifoldgen.tasks import Task, code_types
from manifoldgen.training import DIMENSION_ROWS, VALIDATION, check_unused, manifold_dimension, split

SWEEP_FILE = "sweep.json"
MODEL_FILES = ("model.safetensors", "model.json", "training.json", "loss.png")  # what a candidate's folder holds
MAX_CANDIDATES = 1000


def candidates(models: list[str], latents: list[int], seeds: list[int]) -> list[tuple[str, int | None, int]]:
    """``(model, latent or None, seed)`` for every combination; a model without a latent once per seed."""
    if not models or not seeds:
        raise ManifoldgenError("a sweep needs at least one --model and one --seed")
    for name in models:
        if name not in MODELS.names():
            raise ManifoldgenError(f"unknown model '{name}'; known: {', '.join(MODELS.names())}")
    for latent in latents:
        if isinstance(latent, bool) or not isinstance(latent, int) or not 1 <= latent <= 256:
            raise ManifoldgenError(f"--latent must be an integer from 1 to 256, got {latent!r}")
    seeds = [check_seed(s) for s in seeds]
    found = []
    for model in dict.fromkeys(models):
        sizes = list(dict.fromkeys(latents)) if latents and "latent" in get_model_class(model).defaults else [None]
        found += [(model, latent, seed) for latent in sizes for seed in dict.fromkeys(seeds)]
    if len(found) > MAX_CANDIDATES:
        raise ManifoldgenError(f"{len(found)} candidates; a sweep trains at most {MAX_CANDIDATES}")
    return found


def candidate_name(model: str, latent: int | None, seed: int) -> str:
    return check_name(f"{model}{'' if latent is None else f'-latent{latent}'}-seed{seed}", "candidate")


def train_candidate(dataset: Dataset, model: str, latent: int | None, seed: int, epochs: int | None) -> dict:
    """Train and score one candidate in a temporary folder: ``{"row": ..., "files": {name: bytes}}`` (the files of
    :data:`MODEL_FILES`); the row holds ``model``, ``latent`` (as trained), ``seed``, ``accuracy``, ``recall``,
    ``epochs``, ``seconds``."""
    set_threads()
    task = dataset_task(dataset)
    held_out = split(len(dataset), VALIDATION, torch.Generator().manual_seed(seed))[0].numpy()  # fit's own split
    with tempfile.TemporaryDirectory(prefix="manifoldgen-sweep-") as folder, warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".* is below the constraint manifold's dimension")  # see sweep
        net = get_model_class(model)(**({} if latent is None else {"latent": latent}))
        log = net.fit(dataset, epochs=epochs, seed=seed, out=folder, progress=False, task=task)
        trained = load_model(folder)
        row = {"model": model, "latent": trained.config.get("latent"), "seed": seed,
               **score(trained, task, dataset.q[held_out], dataset.y[held_out], seed),
               "epochs": len(log.history), "seconds": round(float(log.seconds), 1)}
        files = {name: (Path(folder) / name).read_bytes() for name in MODEL_FILES}
    return {"row": row, "files": files}


def rank(rows: list[dict]) -> list[dict]:
    """``rows`` best first: within :data:`RECALL_SLACK` of the best recall by accuracy, then the rest by recall."""
    best = max(row["recall"] for row in rows)
    return sorted(rows, key=lambda r: (r["recall"] < best - RECALL_SLACK,
                                       -(r["accuracy"] if r["recall"] >= best - RECALL_SLACK else r["recall"]),
                                       -r["recall"], r["name"]))


def _settings(dataset: Dataset, jobs: list[tuple], epochs: int | None) -> dict:
    digest = hashlib.sha256(np.ascontiguousarray(dataset.q).tobytes() + np.ascontiguousarray(dataset.y).tobytes())
    return {"dataset_sha256": digest.hexdigest(), "candidates": [list(job) for job in jobs], "epochs": epochs}


def _finished(out: Path, settings: dict) -> dict[str, dict]:
    """The rows of an earlier run of the same sweep whose candidate folders are complete (none without one)."""
    path = out / SWEEP_FILE
    if not path.is_file():
        if (out / "model.json").exists():
            raise ManifoldgenError(f"{out} holds a model that no sweep made (no {SWEEP_FILE}); choose another folder, "
                                   "or delete it to sweep anew")
        return {}
    try:
        old = json.loads(path.read_text())
        rows = {row["name"]: row for row in old["candidates"]}
        damaged = next((f"{name}: {why}" for name, row in rows.items() if (why := _row_problem(row))), "")
    except (ValueError, KeyError, TypeError):
        damaged = "not the JSON a sweep writes"
    if damaged:
        raise ManifoldgenError(f"{path} is damaged ({damaged}); delete it to start the sweep over")
    if old.get("settings") != settings:
        changed = differences(old.get("settings"), settings)
        raise ManifoldgenError(f"{out} holds a sweep made with other settings ({changed}); rerun the same command to "
                               "resume it, or choose another folder")
    names = {candidate_name(*job) for job in settings["candidates"]}
    foreign = next((name for name in rows if name not in names), None)
    if foreign is not None:
        raise ManifoldgenError(f"{path} holds a row named {short(foreign)}, not a candidate of its settings (the file "
                               "was edited); delete it to start the sweep over")
    return {name: row for name, row in rows.items()
            if all((out / "candidates" / name / file).is_file() for file in MODEL_FILES)}


def _row_problem(row: dict) -> str:
    """What is wrong with a candidate's row read back from a sweep file ('' when nothing): its scores rank the
    candidates, so they must be what :func:`train_candidate` writes."""
    for key in ("accuracy", "recall"):
        value = row.get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 1:
            return f"{key} is {value!r}, not a share from 0 to 1"
    if not isinstance(row.get("model"), str) or isinstance(row.get("seed"), bool) or not isinstance(row.get("seed"), int):
        return "its model or seed is missing"
    return ""


def _write(out: Path, settings: dict, rows: list[dict]) -> None:
    atomic_write_text(out / SWEEP_FILE, json.dumps({"rule": f"most accurate within {RECALL_SLACK} of the best "
                                                            "recall, then the others by recall",
                                                    "settings": settings, "candidates": rows}, indent=1))


def sweep(dataset: Dataset, out: str | Path, *, models: list[str], latents: list[int], seeds: list[int],
          epochs: int | None = None, cluster: Cluster | None = None, progress: bool = True) -> list[dict]:
    """Train every candidate (:func:`candidates`; here one after the other, or as tasks on ``cluster``), write
    them, the ranked table and the best model into ``out``; return the ranked rows (``name``, ``rank``,
    ``chosen`` added to :func:`train_candidate`'s row)."""
    if epochs is not None and epochs <= 0:
        raise ManifoldgenError(f"--epochs must be positive, got {epochs}")
    if code_types(dataset.meta.get("task")):
        raise ManifoldgenError("a sweep rebuilds the dataset's task from its meta, which never imports a user's "
                               "module:Class constraint; train those models one by one with `manifoldgen train`")
    task = dataset_task(dataset)  # a dataset no task can be rebuilt from fails here, before any training
    out = Path(out)
    jobs = candidates(models, latents, seeds)
    settings = _settings(dataset, jobs, epochs)
    check_unused(out, ("model.json", SWEEP_FILE, "candidates"))
    done = _finished(out, settings)  # a refusal comes before any warning: one line
    _warn_small_latents(task, dataset, sorted({latent for _, latent, _ in jobs if latent is not None}))
    (out / "candidates").mkdir(parents=True, exist_ok=True)
    rows = list(done.values())
    todo = [job for job in jobs if candidate_name(*job) not in done]
    with progress_bar("training candidates", len(todo), progress) as bar:
        for job, result in _train(dataset, todo, epochs, cluster):
            name = candidate_name(*job)
            for file, blob in result["files"].items():
                atomic_write_bytes(out / "candidates" / name / file, blob)
            rows.append({"name": name, **result["row"], **result.get("node", {})})
            _write(out, settings, rows)
            bar.advance()
    ranked = rank(rows)
    for i, row in enumerate(ranked):
        row["rank"], row["chosen"] = i + 1, i == 0
    for file in MODEL_FILES:
        atomic_write_bytes(out / file, (out / "candidates" / ranked[0]["name"] / file).read_bytes())
    _write(out, settings, ranked)
    return ranked


def _warn_small_latents(task: Task, dataset: Dataset, latents: list[int]) -> None:
    """Warn, once for the sweep, about latent sizes below the manifold's dimension (the candidates' own warnings
    are silenced: they would name train's option)."""
    dimension = manifold_dimension(task, dataset.q[:DIMENSION_ROWS], dataset.y[:DIMENSION_ROWS])
    small = [latent for latent in latents if latent < dimension]
    if small:
        warnings.warn(f"--latent {', '.join(map(str, small))} is below the constraint manifold's dimension "
                      f"{dimension} (joints minus the constraint Jacobian's rank): those candidates' samples cover "
                      f"at most a sheet of it; sweep with --latent {dimension} (or more)", stacklevel=3)


def _train(dataset: Dataset, todo: list[tuple], epochs: int | None, cluster: Cluster | None):
    """``(job, result)`` of :func:`train_candidate` for each job, in the order they finish (on ``cluster``: with
    the ``node`` it ran on)."""
    if cluster is None:
        for job in todo:
            yield job, train_candidate(dataset, *job, epochs)
        return
    with connect(cluster) as pool:
        shared = pool.put(dataset)
        for index, result, node in pool.map_unordered(train_candidate, [(shared, *job, epochs) for job in todo]):
            yield todo[index], {**result, "node": node}
