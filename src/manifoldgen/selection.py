"""The default model, chosen on held-out rows and on the task's own scenes: ``manifoldgen train DATASET``
(``--model auto``).

Each candidate model (:data:`CANDIDATES`, every size from the data: :meth:`ConditionalSampler.size_for`)
is trained with the same seed into ``OUT/candidates/NAME``; on the rows training held out (the same split
for all) each is scored at every condition value there: ``accuracy``, the share of its raw samples within
tolerance, and ``recall``, the share of held-out rows that some sample comes near (k-NN recall,
:func:`manifoldgen.metrics.prdc`). The rule's model is the most accurate of those whose recall is within
:data:`RECALL_SLACK` of the best recall (a model that misses an IK branch fails queries there; a less accurate
one only refines more). The candidates train side by side (as many processes as there are CPUs: this one trains
the first, child processes the others), each as it would alone: the same bytes as a sequential run. Each
process scores and races the candidate it trained as soon as it is trained, and a child races the projection
sampler, so that a candidate that trains faster is priced while the slowest still trains.

Held-out rows do not price what planning pays: a flow-matching model covers more but decodes a row in tens to
hundreds of microseconds, and on a codimension-one manifold projected uniform rows are as good and cost nothing.
So when the task names scenes (or its dataset recorded them), :func:`race` plans them (:data:`RACE_SEEDS` seeds
each, seeds no benchmark uses) with every candidate's sampler and with the projection sampler (``project``:
kept as the rule's model at ``mix`` 1, which a model sampler spec then maps to the projection sampler), and the
chosen model is the race's winner: most runs solved, then the least median CPU time. Its files are
copied to ``OUT`` with its ``mix``; ``OUT/selection.json`` holds both tables. Without scenes the rule decides.

Where one candidate is the more accurate and the other the more covering, a third is scored and raced: the
accurate one with :data:`BLEND_SHARE` of its rows drawn from the covering one (``cvae+cfm``, saved in
``OUT/candidates/cvae+cfm`` with its partner in ``blend/``): most of the one's accuracy, most of the other's recall.
"""

from __future__ import annotations

import copy
import json
import math
import multiprocessing
import os
import shutil
import statistics
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import torch

from manifoldgen.dataset import Dataset
from manifoldgen.errors import ManifoldgenError, differences
from manifoldgen.io import atomic_write_text, locks_output
from manifoldgen.metrics import joint_features, prdc
from manifoldgen.models import get_model_class, load_model
from manifoldgen.models.base import CONFIG_FILE, ConditionalSampler, dataset_task
from manifoldgen.models.files import BLEND_DIR
from manifoldgen.models.loss_curve import plot_training
from manifoldgen.runtime import CANDIDATES
from manifoldgen.scene import Scene
from manifoldgen.tasks import Task, code_files, task_in_child
from manifoldgen.training import (CHECKPOINT, VALIDATION, TrainingLog, check_dataset, check_unused, fingerprint, split,
                                  train)

RECALL_SLACK = 0.1  # candidates within this recall of the best compete on accuracy
BLEND_SHARE = 0.2  # the share of rows the most covering candidate gives the most accurate one's blend
SCORED_CONDITIONS = 6  # condition values scored (spread over the held-out ones)
SAMPLES = 1000  # samples drawn per scored condition value
K = 5  # neighbours of the k-NN recall
SELECTION_FILE = "selection.json"
PARALLEL_ROWS = 2000  # from this many rows on, candidates train in parallel (below, starting processes costs more)
RACE_SCENES = 3  # at most this many of the task's scenes are raced
RACE_SEEDS = 3  # planning runs per scene and sampler in the race
RACE_SEED = 10_000  # the race's first seed (benchmarks use seeds from 0)
RACE_TIME = 5.0  # seconds a race run may plan (an unsolved run counts this much CPU)
PROJECTION = "project"  # the race's entry for the projection sampler


@locks_output("out")  # one training per model directory
def select_model(dataset: Dataset, out: str | Path, *, seed: int = 0, epochs: int | None = None,
                 resume: bool = False, progress: bool = True, task: Task | None = None,
                 workers: int | None = None, race_scenes: bool = True,
                 ) -> tuple[ConditionalSampler, list[dict], list[dict]]:
    """Train every candidate, score it on the held-out rows, race it on the task's scenes (:func:`race`), write
    the chosen one to ``out``; returns it, the table (one dict per candidate: ``model``, ``accuracy``,
    ``recall``, ``epochs``, ``seconds``, ``chosen``) and the race's (see :func:`race`, plus ``chosen``). A
    candidate already trained in ``out/candidates`` is reused; one interrupted resumes with ``resume``.
    ``workers``: processes training side by side (default: one per CPU and candidate for datasets of
    :data:`PARALLEL_ROWS` rows or more, else 1; a child imports a user constraint's module from the file this
    process imported it from); ``race_scenes`` False: the rule alone chooses."""
    if task is None:
        task = dataset_task(dataset)
        check_dataset(dataset, task)
    out = Path(out)
    if resume and not any((out / "candidates" / name / CHECKPOINT).exists() for name in CANDIDATES):
        raise ManifoldgenError(f"no checkpoint in {out}/candidates to resume (training finished or never started); "
                               "run without --resume")
    recorded = check_recorded_scenes(dataset)
    check_unused(out, (CONFIG_FILE, "candidates"))
    if (out / CONFIG_FILE).exists() and not (out / SELECTION_FILE).exists():
        raise ManifoldgenError(f"{out} holds a model trained alone (no {SELECTION_FILE}); choose another directory "
                               "(-o), or delete it to train anew")
    (out / "candidates").mkdir(parents=True, exist_ok=True)
    held_out = split(len(dataset), VALIDATION, torch.Generator().manual_seed(seed))[0].numpy()
    folders = {name: out / "candidates" / name for name in CANDIDATES}
    linked = next((f for f in (out / "candidates", *folders.values()) if f.is_symlink()), None)
    if linked is not None:
        raise ManifoldgenError(f"{linked} is a symbolic link; train writes its candidates into folders of its own: "
                               "remove the link or choose another directory (-o)")
    todo = [name for name, folder in folders.items()
            if not (folder / CONFIG_FILE).exists() or (folder / CHECKPOINT).exists()]
    for name in set(folders) - set(todo):
        _check_reused(folders[name], dataset, seed, epochs)
    held = (dataset.q[held_out], dataset.y[held_out])
    scenes = race_documents(task, recorded) if race_scenes else []
    jobs = [(name, dataset, epochs, seed, folders[name], name in todo,
             resume and (folders[name] / CHECKPOINT).exists()) for name in CANDIDATES]
    if workers is None:
        workers = (os.cpu_count() or 1) if len(dataset) >= PARALLEL_ROWS else 1
    spec = task.spec()
    files = code_files(spec)  # a child imports the task's user modules from the files this process imported
    if min(len(todo), workers) > 1 and all(files.values()):
        child = (spec, files, torch.get_num_threads())
        pool = ProcessPoolExecutor(min(len(jobs), workers) - 1, mp_context=multiprocessing.get_context("spawn"))
        try:
            others = [pool.submit(_candidate, job, held, scenes, child) for job in jobs[1:]]
            projection = pool.submit(_race_in_child, child, scenes) if scenes else None
            log = _trained(jobs[0], task, progress)
            plot = pool.submit(plot_training, log, jobs[0][4] / "loss.png") if log else None
            pool.shutdown(wait=False)  # no more work: the children exit once theirs is done, while this goes on
            done = [_priced(jobs[0], held, scenes, task, progress)] + [future.result() for future in others]
            projection = projection.result() if projection else None
            if plot:
                plot.result()
        finally:
            pool.shutdown(wait=False, cancel_futures=True)
    else:
        done = [_candidate(job, held, scenes, task=task, progress=progress) for job in jobs]
        projection = race({PROJECTION: None}, task, scenes, progress=progress)[PROJECTION] if scenes else None
    table = [result["row"] for result in done]
    raced = {result["row"]["model"]: result["race"] for result in done if result["race"]}
    models = {name: load_model(folder) for name, folder in folders.items()}
    blend = blended(models, table)
    if blend is not None:  # saved beside the others, so that it can be sampled and benchmarked as they can
        (out / "candidates" / blend.label).mkdir(exist_ok=True)
        blend.save(out / "candidates" / blend.label)
        models[blend.label] = blend
        table.append({"model": blend.label, **score(blend, task, *held, seed), "blend": BLEND_SHARE})
        if scenes:
            raced |= race({blend.label: blend}, task, scenes, progress=progress)
    best_recall = max(row["recall"] for row in table)
    ruled = max((row for row in table if row["recall"] >= best_recall - RECALL_SLACK), key=lambda r: r["accuracy"])
    raced = [{"label": name, "model": name, "mix": 0.0, **raced[name]} for name in models] + \
        [{"label": PROJECTION, "model": ruled["model"], "mix": 1.0, **projection}] if scenes else []
    winner = max(raced, key=lambda r: (r["solved"], -r["cpu"])) if raced else None
    name = winner["model"] if winner else ruled["model"]
    for row in table:
        row["chosen"] = row["model"] == name
    for row in raced:
        row["chosen"] = row is winner
    model = models[name]
    model.mix = winner["mix"] if winner else None
    model.save(out)
    if model.blend is None:
        shutil.rmtree(out / BLEND_DIR, ignore_errors=True)  # a blend kept by an earlier run of this directory
    for file in ("training.json", "loss.png"):
        shutil.copyfile(out / "candidates" / model.name / file, out / file)
    atomic_write_text(out / SELECTION_FILE, json.dumps({
        "rule": f"most accurate within {RECALL_SLACK} of the best recall; then, where the task names scenes, the "
                f"race's winner (most of {RACE_SEEDS} runs per scene solved, then least median CPU)",
        "candidates": table, "race": raced}, indent=1))
    return model, table, raced


def blended(models: dict[str, ConditionalSampler], table: list[dict]) -> ConditionalSampler | None:
    """The most accurate candidate with :data:`BLEND_SHARE` of its rows drawn from the most covering one (its
    ``refine``: the larger of the two), or None where one candidate is both."""
    accurate = max(table, key=lambda row: row["accuracy"])["model"]
    covering = max(table, key=lambda row: row["recall"])["model"]
    if accurate == covering:
        return None
    blend = copy.copy(models[accurate])  # its networks shared, its blend and refine its own
    blend.blend = (models[covering], BLEND_SHARE)
    refines = [m.refine for m in (blend, models[covering]) if m.refine is not None]
    blend.refine = max(refines) if refines else None
    return blend


def race_documents(task: Task, recorded: list[dict] = ()) -> list[dict]:
    """The scenes the race plans, as solved scene documents (:func:`manifoldgen.scene.solved_document`): up to
    :data:`RACE_SCENES` of ``task``'s scene files (one that cannot be set up is left out: collect already warned),
    else of the scene documents ``recorded`` in the dataset's meta (a task rebuilt from a file's meta)."""
    from manifoldgen.scene import get_scene, solved_document

    if not task.scenes:
        return list(recorded)[:RACE_SCENES]
    documents = []
    for name in list(task.scenes)[:RACE_SCENES]:
        try:
            documents.append(solved_document(get_scene(task, name), name))
        except ManifoldgenError:
            continue
    return documents


def race(models: dict[str, ConditionalSampler | None], task: Task, scenes: list[dict], *,
         progress: bool = False) -> dict[str, dict]:
    """Plan each scene document of ``scenes`` (:func:`race_documents`) :data:`RACE_SEEDS` times (RRT-Connect, its
    task settings, :data:`RACE_TIME` seconds) with each model's sampler (None: the projection sampler,
    :data:`PROJECTION`); per label: ``solved``, ``runs`` and ``cpu`` (median CPU seconds of a run, unsolved ones
    counted at the time limit)."""
    from manifoldgen.progress import progress_bar
    from manifoldgen.query import get_planner, task_settings
    from manifoldgen.sampling import ModelSampler, ProjectionSampler
    from manifoldgen.space import ConstrainedSpace

    runs = {label: [] for label in models}
    planner_type = get_planner("rrtconnect")
    settings = planner_type.settings_type(**task_settings(task, "rrtconnect"))
    with progress_bar(f"racing {', '.join(models)} on the task's scenes", len(models) * len(scenes) * RACE_SEEDS,
                      progress) as bar:
        for doc in scenes:
            scene = Scene.from_json(json.dumps(doc), f"scene {doc.get('name')}")
            space = ConstrainedSpace(task.constraint, task.condition.check(scene.condition)[0],
                                     scene.checker(task.robot))
            for label, model in models.items():
                for seed in range(RACE_SEED, RACE_SEED + RACE_SEEDS):
                    sampler = (ProjectionSampler(space, seed=seed) if model is None else
                               ModelSampler(space, model, seed=seed))
                    planner = planner_type(space, sampler, seed=seed, settings=settings)
                    begin = time.process_time()
                    result = planner.solve(scene.start, scene.goal, RACE_TIME)
                    cpu = time.process_time() - begin  # the search alone, as `bench` times it
                    solved = result.solved and space.validate_path(result.path).valid
                    runs[label].append((solved, cpu if solved else max(cpu, RACE_TIME)))
                    bar.advance()
    return {label: {"solved": sum(ok for ok, _ in rows), "runs": len(rows),
                    "cpu": round(statistics.median(cpu for _, cpu in rows), 4)} for label, rows in runs.items()}


def check_recorded_scenes(dataset: Dataset) -> list[dict]:
    """The scene documents the dataset's meta records (the race plans them, a trained model's meta keeps them), each
    read whole, before any training; a damaged one is refused in one line."""
    recorded = dataset.meta.get("scenes") or []
    for i, doc in enumerate(recorded):
        try:
            Scene.from_json(json.dumps(doc), f"the dataset's scenes[{i}]")
        except ManifoldgenError as exc:
            raise ManifoldgenError(f"{exc}; the dataset was edited or is damaged: collect it again") from None
    return recorded


def _training_log(folder: Path) -> dict:
    """A candidate's training.json, refused in one line unless it holds what training writes (its epochs, seconds
    and, when it diverged, where)."""
    try:
        log = json.loads((folder / "training.json").read_text())
        ok = (isinstance(log["history"], list) and isinstance(log["seconds"], (int, float))
              and not isinstance(log["seconds"], bool) and math.isfinite(log["seconds"]) and log["seconds"] >= 0)
    except (OSError, ValueError, KeyError, TypeError):
        ok = False
    if not ok:
        raise ManifoldgenError(f"{folder / 'training.json'} is damaged (not the log training writes); delete the "
                               f"folder {folder} to train that candidate again")
    return log


def _check_reused(folder: Path, dataset: Dataset, seed: int, epochs: int | None) -> None:
    """Refuse to reuse the finished candidate in ``folder`` when it was trained on other rows, with another seed or
    validation share, or (``epochs`` given) for another number of epochs than this run asks for."""
    made = _training_log(folder).get("identity")
    made = made if isinstance(made, dict) else {}
    wanted = {"dataset": fingerprint(dataset), "seed": seed, "validation": VALIDATION,
              **({"epochs": epochs} if epochs is not None else {})}
    changed = differences({key: made.get(key) for key in wanted}, wanted)
    if changed:
        raise ManifoldgenError(f"{folder} holds a candidate trained with other settings ({changed}); choose another "
                               "directory (-o), or delete it to train anew")


def _candidate(job: tuple, held: tuple[np.ndarray, np.ndarray], scenes: list[dict], child: tuple | None = None, *,
               task: Task | None = None, progress: bool = False) -> dict:
    """One candidate ``(name, dataset, epochs, seed, folder, train, resume)``: trained into its folder for
    ``task`` unless ``train`` is False (a finished one, reused) and its loss curves drawn (``loss.png``), then
    scored on the held-out rows ``held`` ``(q (N, n), y (N, k))`` and raced on ``scenes`` (:func:`_priced`). In
    a child process ``task`` is None: rebuilt by :func:`task_in_child` from ``child`` ``(spec, files, torch
    threads)``."""
    if task is None:
        task = _child_task(child)
    log = _trained(job, task, progress)
    if log:
        plot_training(log, job[4] / "loss.png")
    return _priced(job, held, scenes, task, progress)


def _trained(job: tuple, task: Task, progress: bool) -> TrainingLog | None:
    """The training log of the candidate ``job`` (see :func:`_candidate`) trained now, or None where it is
    reused."""
    name, dataset, epochs, seed, folder, trains, resume = job
    if not trains:
        return None
    return train(get_model_class(name)(), dataset, task=task, epochs=epochs, seed=seed, progress=progress,
                 out=folder, resume=resume)


def _priced(job: tuple, held: tuple[np.ndarray, np.ndarray], scenes: list[dict], task: Task,
            progress: bool) -> dict:
    """The trained candidate ``job`` (see :func:`_candidate`) scored on ``held`` and raced on ``scenes``: its
    table ``row`` and its ``race`` result ({} without scenes)."""
    name, _, _, seed, folder = job[:5]
    model = load_model(folder)
    log = _training_log(folder)
    row = {"model": name, **score(model, task, *held, seed), "epochs": len(log["history"]),
           "seconds": round(float(log["seconds"]), 1),
           **({"diverged_at": log["diverged_at"], "best_epoch": log["best_epoch"]} if log.get("diverged_at") else {})}
    return {"row": row, "race": race({name: model}, task, scenes, progress=progress)[name] if scenes else {}}


def _race_in_child(child: tuple, scenes: list[dict]) -> dict:
    """The projection sampler's race (:func:`race`) in a child process, for the task ``child`` describes."""
    return race({PROJECTION: None}, _child_task(child), scenes)[PROJECTION]


def _child_task(child: tuple) -> Task:
    """In a child process: torch at the parent's thread count, and the task ``child`` ``(spec, files, threads)``
    describes (:func:`task_in_child`)."""
    from manifoldgen.runtime import set_threads

    spec, files, threads = child
    set_threads(threads)
    return task_in_child(spec, files)


def score(model: ConditionalSampler, task: Task, q: np.ndarray, y: np.ndarray, seed: int) -> dict:
    """Mean ``accuracy`` (raw samples within tolerance) and ``recall`` (k-NN, joint-range scaled) of ``model``
    against held-out rows ``q (N, n)`` at conditions ``y (N, k)``, over at most :data:`SCORED_CONDITIONS` values
    (recall 0 where no value has more than :data:`K` held-out rows)."""
    values = np.unique(y, axis=0)
    values = values[np.unique(np.linspace(0, len(values) - 1, min(len(values), SCORED_CONDITIONS)).astype(int))]
    accuracy, recall = [], []
    lower, upper = task.robot.lower, task.robot.upper
    for i, value in enumerate(values):
        rows = q[np.all(y == value, axis=1)]
        samples = model.sample(value, SAMPLES, torch.Generator().manual_seed(seed + i))
        accuracy.append(float(task.constraint.satisfied(samples, value).mean()))
        if len(rows) > K:
            recall.append(prdc(joint_features(rows, lower, upper), joint_features(samples, lower, upper), K).recall)
    return {"accuracy": round(float(np.mean(accuracy)), 4),
            "recall": round(float(np.mean(recall)) if recall else 0.0, 4)}  # too few held-out rows: no evidence
