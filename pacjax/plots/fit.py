"""Figures of an identification: loss curve, predicted vs measured backbones, error histogram.

Matplotlib on :class:`~matplotlib.figure.Figure` objects with the Agg canvas (no pyplot state).
Lengths in mm, in the motion-capture frame (the model's backbones are moved there with the
fitted transform).
"""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .._identify.report import IdentificationReport
from .._model.query import backbone
from .._model.scene import Scene

__all__ = ["plot_loss", "plot_backbones", "plot_error_histogram"]


def _save(fig: Figure, path) -> None:
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=110, bbox_inches="tight")


def plot_loss(report: IdentificationReport, path) -> None:
    """Normalised loss and training RMSE (mm) against the iteration."""
    fig = Figure(figsize=(7.0, 3.2))
    ax1, ax2 = fig.subplots(1, 2)
    it = np.arange(len(report.loss_history))
    ax1.semilogy(it, np.maximum(report.loss_history, 1e-300), "o-")
    ax1.set_xlabel("iteration")
    ax1.set_ylabel("loss / observation")
    ax1.set_title("loss")
    ax2.semilogy(it, np.maximum(report.rmse_history_mm, 1e-12), "o-", color="#d62728")
    ax2.set_xlabel("iteration")
    ax2.set_ylabel("marker RMSE (mm)")
    ax2.set_title("training error")
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    _save(fig, path)


def plot_backbones(
    scene: Scene, report: IdentificationReport, path, n_frames: int = 6, held_out: bool = True
) -> None:
    """Predicted backbones (lines) and measured markers (crosses) of a few frames, in two
    projections of the mocap frame (the two axes with the largest spread)."""
    errors = report.validation if held_out and report.validation is not None else report.train
    label = "held-out" if errors is report.validation else "train"
    frames = np.linspace(0, len(errors.q) - 1, min(n_frames, len(errors.q))).round().astype(int)
    curves = []
    for f in np.unique(frames):
        pos, _ = backbone(scene, errors.q[f], 40)
        curves.append((f, np.asarray(pos) @ report.rotation.T + report.translation))
    points = np.concatenate(
        [c for _, c in curves] + [errors.measured[np.unique(frames)].reshape(-1, 3)]
    )
    spread = np.nanmax(points, 0) - np.nanmin(points, 0)
    a, b, c = np.argsort(spread)[::-1]
    fig = Figure(figsize=(9.0, 4.2))
    axes = fig.subplots(1, 2)
    colors = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b")
    for ax, (i, j) in zip(axes, ((a, b), (a, c)), strict=True):
        for k, (f, curve) in enumerate(curves):
            col = colors[k % len(colors)]
            ax.plot(1e3 * curve[:, i], 1e3 * curve[:, j], "-", color=col, lw=2, label=f"frame {f}")
            m = errors.measured[f]
            ax.plot(1e3 * m[:, i], 1e3 * m[:, j], "x", color=col, ms=7, mew=2)
        ax.set_xlabel(f"{'xyz'[i]} (mm, mocap)")
        ax.set_ylabel(f"{'xyz'[j]} (mm, mocap)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=7, loc="best")
    fig.suptitle(f"Fitted model (lines) vs measured markers (x), {label} frames")
    fig.tight_layout()
    _save(fig, path)


def plot_error_histogram(report: IdentificationReport, path) -> None:
    """Histogram of marker distance errors (mm), train and held-out."""
    fig = Figure(figsize=(6.0, 3.4))
    ax = fig.subplots()
    sets = [("train", report.train)]
    if report.validation is not None:
        sets.append(("held-out", report.validation))
    all_err = []
    for _, e in sets:
        d = 1e3 * np.linalg.norm(e.predicted - e.measured, axis=-1)
        all_err.append(d[np.isfinite(d)])
    top = max(float(np.max(x)) for x in all_err if x.size) or 1.0
    bins = np.linspace(0.0, top, 30)
    for (name, _), d in zip(sets, all_err, strict=True):
        ax.hist(d, bins=bins, alpha=0.6, label=f"{name} (RMSE {np.sqrt(np.mean(d**2)):.2f} mm)")
    ax.set_xlabel("marker error (mm)")
    ax.set_ylabel("count")
    ax.legend()
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    _save(fig, path)
