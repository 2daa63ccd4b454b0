"""Loss curves of a training run (``loss.png`` in every model directory)."""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING

from manifoldgen.io import atomic_write_bytes

if TYPE_CHECKING:
    from manifoldgen.training import TrainingLog


def save_figure(fig, path: str | Path) -> None:
    """Write a matplotlib figure as PNG atomically and close it."""
    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(Path(path), buffer.getvalue())


def plot_training(log: TrainingLog, path: str | Path) -> None:
    """Per-epoch mean training losses (left) and validation score with the best epoch (right)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    epochs = [h["epoch"] for h in log.history]
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.6))
    for key in (log.history[0]["train"] if log.history else {}):
        if key != "skipped":  # the share of steps skipped for a non-finite loss: said in the title
            left.plot(epochs, [h["train"][key] for h in log.history], label=key)
    left.set_yscale("symlog", linthresh=1e-2)
    left.set_xlabel("epoch")
    skipped = sum(h["train"].get("skipped", 0.0) for h in log.history)
    left.set_title(f"{log.model}: training losses" + (" (steps with a non-finite loss skipped)" if skipped else ""))
    left.legend(fontsize=8)
    right.plot(epochs, [h["val"] for h in log.history], color="k")
    if log.best_epoch:
        right.axvline(log.best_epoch, color="tab:green", ls="--", label=f"best epoch {log.best_epoch}")
        right.legend(fontsize=8)
    right.set_xlabel("epoch")
    right.set_title("validation score (lower is better)")
    save_figure(fig, path)
