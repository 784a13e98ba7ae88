"""PNG plots of evaluation (PR curve, PE by distance) and training (loss and metric curves)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_pr_curve(precision: NDArray[np.float64], recall: NDArray[np.float64], path: Path,
                  title: str) -> None:
    plt = _pyplot()
    figure, axes = plt.subplots(figsize=(5, 4))
    axes.plot(recall, precision, lw=1.5)
    axes.set_xlabel("recall")
    axes.set_ylabel("precision")
    axes.set_xlim(0, 1)
    axes.set_ylim(0, 1.02)
    axes.set_title(title)
    axes.grid(alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def plot_pe_by_distance(distances_m: NDArray[np.float64], errors_m: dict[str, NDArray[np.float64]],
                        path: Path, title: str) -> None:
    """Scatter of each placement's errors (label -> (M,) m) against GT distance (M,) m, and their
    mean per 2 m bin."""
    plt = _pyplot()
    figure, axes = plt.subplots(figsize=(6, 4))
    colours = dict(zip(errors_m, ("tab:blue", "tab:green", "tab:orange", "tab:red"), strict=False))
    for label, error in errors_m.items():
        axes.scatter(distances_m, error, s=4, alpha=0.2, color=colours[label])
    if len(distances_m):
        edges = np.arange(0.0, math.ceil(float(distances_m.max()) / 2) * 2 + 2.0, 2.0)
        bins = [(low, high) for low, high in itertools.pairwise(edges)
                if ((distances_m >= low) & (distances_m < high)).any()]
        centres = [(low + high) / 2 for low, high in bins]
        for label, error in errors_m.items():
            means = [float(error[(distances_m >= low) & (distances_m < high)].mean()) for low, high in bins]
            axes.plot(centres, means, "-o", color=colours[label], label=f"{label} (mean)")
        axes.legend()
    axes.set_xlabel("distance from nadir (m)")
    axes.set_ylabel("localisation error (m)")
    axes.set_title(title)
    axes.grid(alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def plot_training(records: Sequence[dict[str, Any]], path: Path) -> None:
    """Loss terms and validation metrics per epoch from the training log's records."""
    plt = _pyplot()
    figure, (loss_axes, metric_axes) = plt.subplots(1, 2, figsize=(10, 4))
    epochs = [r["epoch"] for r in records]
    for key in ("total", "heatmap", "size", "offset", "equivariance"):
        values = [r.get("train", {}).get(key) for r in records]
        if any(v is not None for v in values):
            loss_axes.plot(epochs, [np.nan if v is None else v for v in values], label=key)
    loss_axes.set_yscale("log")
    loss_axes.set_xlabel("epoch")
    loss_axes.set_title("training loss")
    loss_axes.legend()
    for key in ("AP50", "mAP", "recall", "precision", "mPE"):
        values = [r.get("val", {}).get(key) for r in records]
        if any(v is not None for v in values):
            metric_axes.plot(epochs, [np.nan if v is None else v for v in values], "-o", label=key)
    metric_axes.set_xlabel("epoch")
    metric_axes.set_title("validation")
    if metric_axes.get_legend_handles_labels()[0]:
        metric_axes.legend()
    else:  # trained without --val
        metric_axes.text(0.5, 0.5, "no validation set", ha="center", va="center",
                         transform=metric_axes.transAxes)
    for axes in (loss_axes, metric_axes):
        axes.grid(alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)
