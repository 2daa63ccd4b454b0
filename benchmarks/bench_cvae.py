"""CVAE settings compared: training time against held-out accuracy and recall, per dataset.

    python benchmarks/bench_cvae.py DATA.npz... --variants 'encoder_hidden=[64,64]' 'encoder_hidden=[256,256,256]'
    python benchmarks/bench_cvae.py DATA.npz --task TASK.toml --variants ...   # a user constraint's dataset

For each dataset, one CVAE per ``--variants`` entry (``KEY=VALUE`` hyper-parameters, ``;`` between them, each
value as ``--set`` reads it; the rest at the defaults and at the sizes the data gives), trained side by side, one
process each (as ``train`` trains its candidates), then scored as ``train`` scores its candidates on the rows
training held out: ``accuracy`` (raw samples within tolerance) and k-NN ``recall``. Prints one Markdown row per
dataset and variant: the decoder's and encoder's layers, epochs run, training seconds (wall), accuracy, recall.
"""

from __future__ import annotations

import argparse
import multiprocessing
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path


def trained(data: str, variant: str, seed: int, task_file: str | None) -> dict:
    """Train one CVAE with the ``variant``'s hyper-parameters on ``data`` (made for the task file ``task_file``,
    else for the task its meta names) and score it on the held-out rows."""
    from manifoldgen.runtime import set_threads

    set_threads()
    import torch

    from manifoldgen.dataset import Dataset
    from manifoldgen.models import CVAE
    from manifoldgen.models.base import dataset_task
    from manifoldgen.selection import score
    from manifoldgen.settings import parse_settings
    from manifoldgen.tasks import load_task_file
    from manifoldgen.training import VALIDATION, split

    dataset = Dataset.load(data)
    task = dataset_task(dataset, load_task_file(task_file) if task_file else None)
    model = CVAE(**parse_settings([entry for entry in variant.split(";") if entry], None, CVAE.defaults, "CVAE"))
    with tempfile.TemporaryDirectory() as out:
        log = model.fit(dataset, seed=seed, out=out, progress=False, task=task)
    held_out = split(len(dataset), VALIDATION, torch.Generator().manual_seed(seed))[0].numpy()
    scores = score(model, task, dataset.q[held_out], dataset.y[held_out], seed)
    return {"epochs": len(log.history), "seconds": log.seconds, "config": model.config, **scores}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("datasets", nargs="+")
    parser.add_argument("--variants", nargs="+", required=True, help="KEY=VALUE;KEY=VALUE per CVAE")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--task", help="the task file every dataset was made for (needed for a user constraint)")
    args = parser.parse_args()
    print("| dataset | variant | decoder | encoder | epochs | train (s, wall) | accuracy | recall |")
    print("|---|---|---|---|---|---|---|---|")
    with ProcessPoolExecutor(len(args.variants), mp_context=multiprocessing.get_context("spawn")) as pool:
        for data in args.datasets:
            runs = len(args.variants)
            rows = pool.map(trained, [data] * runs, args.variants, [args.seed] * runs, [args.task] * runs)
            for variant, row in zip(args.variants, rows):
                config = row["config"]
                print(f"| {Path(data).parent.name} | `{variant}` | {config['hidden']} | {config['encoder_hidden']} | "
                      f"{row['epochs']} | {row['seconds']:.1f} | {row['accuracy']:.3f} | {row['recall']:.3f} |",
                      flush=True)


if __name__ == "__main__":
    from manifoldgen.errors import ManifoldgenError

    try:
        main()
    except ManifoldgenError as exc:
        raise SystemExit(f"error: {exc}") from None
