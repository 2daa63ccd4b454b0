"""Figures of generated samples: end-effector clouds (paper Fig. 2), residual histograms, coverage."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from manifoldgen.io import save_figure


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_end_effector(positions: dict[str, np.ndarray], path: str | Path, title: str = "",
                      max_points: int = 4000) -> None:
    """One 3D panel per model: end-effector positions (N, 3) of its valid samples (magenta dots)."""
    plt = _pyplot()
    fig = plt.figure(figsize=(4.2 * len(positions), 4.4))
    everything = np.concatenate([p for p in positions.values() if len(p)] or [np.zeros((1, 3))])
    low, high = everything.min(0) - 0.05, everything.max(0) + 0.05
    for i, (name, p) in enumerate(positions.items()):
        ax = fig.add_subplot(1, len(positions), i + 1, projection="3d")
        p = p[np.linspace(0, len(p) - 1, min(len(p), max_points)).astype(int)] if len(p) else p
        ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=1, c="m", alpha=0.5, depthshade=False)
        ax.set_xlim(low[0], high[0])
        ax.set_ylim(low[1], high[1])
        ax.set_zlim(low[2], high[2])
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_zlabel("z (m)")
        ax.set_title(f"{name} ({len(positions[name])} valid)")
    if title:
        fig.suptitle(title)
    save_figure(fig, path)


def plot_residuals(violations: dict[str, np.ndarray], path: str | Path) -> None:
    """Histogram per model of the worst |F_i| / tol_i of raw samples (log scale; 1 = tolerance)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 3.8))
    bins = np.logspace(-2, 3, 60)
    for name, v in violations.items():
        ax.hist(np.clip(v, bins[0], bins[-1]), bins=bins, histtype="step", lw=1.5,
                label=f"{name}: {np.mean(v <= 1):.1%} within")
    ax.axvline(1.0, color="k", ls="--", lw=1)
    ax.set_xscale("log")
    ax.set_xlabel("worst residual / tolerance (raw samples)")
    ax.set_ylabel("samples")
    ax.legend(fontsize=8)
    save_figure(fig, path)


def plot_coverage(results: dict, path: str | Path) -> None:
    """Raw validity, k-NN recall and coverage per condition value and model (unseen conditions hollow); conditions
    of several values (``0.3,0``) are placed in order, one tick each."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(14, 3.6))
    panels = (("raw", "raw within-tolerance rate"), ("recall", "k-NN recall vs reference"),
              ("coverage", "k-NN coverage vs reference"))
    keys = list(next(iter(results["models"].values()))["per_condition"]) if results["models"] else []
    scalar = all("," not in k for k in keys)
    for name, entry in results["models"].items():
        items = (sorted((float(y), r) for y, r in entry["per_condition"].items()) if scalar
                 else [(keys.index(y), r) for y, r in entry["per_condition"].items()])
        ys = [y for y, _ in items]
        color = None
        for ax, (key, _) in zip(axes, panels):
            line, = ax.plot(ys, [r[key] for _, r in items], lw=1, label=name, color=color)
            color = line.get_color()
            for y, r in items:
                ax.plot(y, r[key], "o", color=color, mfc=color if r["seen"] else "white")
    for ax, (_, title) in zip(axes, panels):
        ax.set_title(title)
    left = axes[0]
    for ax in axes:
        ax.set_xlabel("condition (hollow: unseen)")
        if not scalar:
            ax.set_xticks(range(len(keys)), keys, rotation=45, ha="right", fontsize=7)
        ax.set_ylim(0, 1.02)
    left.legend(fontsize=8)
    save_figure(fig, path)
