"""The loss curves of a training run (``loss.png`` in every model directory)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from manifoldgen.io import save_figure

if TYPE_CHECKING:
    from manifoldgen.training import TrainingLog


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
