"""Figures of an identification: loss curve, predicted vs measured backbones, error histogram.

Matplotlib on :class:`~matplotlib.figure.Figure` objects with the Agg canvas (no pyplot state).
Lengths in mm, in the motion-capture frame (the model's backbones are moved there with the
fitted transform). Iterations and counts get whole-number ticks, log axes plain numbers
(:mod:`pacjax.plots.ticks`). Each function returns its figure.
"""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.legend_handler import HandlerTuple

from .._identify.report import IdentificationReport
from .._model.query import backbone
from .._model.scene import Scene
from .equilibria import CASE_COLORS
from .ticks import integer_ticks, plain_log_ticks

__all__ = ["plot_loss", "plot_backbones", "plot_error_histogram"]


def _save(fig: Figure, path) -> Figure:
    if path is not None:
        fig.savefig(path, dpi=110, bbox_inches="tight")
    return fig


def _figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def plot_loss(report: IdentificationReport, path=None) -> Figure:
    """Normalised loss and training RMSE (mm) against the iteration."""
    fig = _figure(7.0, 3.2)
    ax1, ax2 = fig.subplots(1, 2)
    it = np.arange(len(report.loss_history))
    curves = (
        (ax1, np.maximum(report.loss_history, 1e-300), CASE_COLORS[0], "loss / observation"),
        (ax2, np.maximum(report.rmse_history_mm, 1e-12), CASE_COLORS[1], "marker RMSE (mm)"),
    )
    for ax, values, color, ylabel in curves:
        ax.semilogy(it, values, "o-", color=color, ms=4)
        ax.set_xlabel("iteration")
        ax.set_ylabel(ylabel)
        integer_ticks(ax.xaxis)
        finite = values[np.isfinite(values)]
        if finite.size:
            plain_log_ticks(ax.yaxis, float(finite.min()), float(finite.max()))
        ax.grid(True, which="both", alpha=0.3)
    ax1.set_title("loss")
    ax2.set_title("training error")
    return _save(fig, path)


def plot_backbones(
    scene: Scene, report: IdentificationReport, path=None, n_frames: int = 6, held_out: bool = True
) -> Figure:
    """Predicted backbones (lines) and measured markers (crosses) of a few frames, in two
    projections of the mocap frame (the two axes with the largest spread); a frame's line and
    crosses share its colour, and its legend entry shows both."""
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
    fig = _figure(9.0, 4.6)
    axes = fig.subplots(1, 2)
    entries = []
    for n, (ax, (i, j)) in enumerate(zip(axes, ((a, b), (a, c)), strict=True)):
        for k, (f, curve) in enumerate(curves):
            col = CASE_COLORS[k % len(CASE_COLORS)]
            (line,) = ax.plot(
                1e3 * curve[:, i], 1e3 * curve[:, j], "-", color=col, lw=2, label=f"frame {f}"
            )
            m = errors.measured[f]
            (cross,) = ax.plot(1e3 * m[:, i], 1e3 * m[:, j], "x", color=col, ms=7, mew=2)
            if n == 0:
                entries.append(((line, cross), f"frame {f}"))
        ax.set_xlabel(f"{'xyz'[i]} (mm, mocap)")
        ax.set_ylabel(f"{'xyz'[j]} (mm, mocap)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(True, alpha=0.3)
    fig.legend(
        [h for h, _ in entries],
        [t for _, t in entries],
        handler_map={tuple: HandlerTuple(ndivide=None)},
        loc="outside right center",
        fontsize=8,
        frameon=False,
    )
    fig.suptitle(f"Fitted model (lines) vs measured markers (x), {label} frames")
    return _save(fig, path)


def plot_error_histogram(report: IdentificationReport, path=None) -> Figure:
    """Histogram of marker distance errors (mm), train and held-out."""
    fig = _figure(6.0, 3.4)
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
    for k, ((name, _), d) in enumerate(zip(sets, all_err, strict=True)):
        ax.hist(
            d,
            bins=bins,
            alpha=0.6,
            color=CASE_COLORS[k],
            label=f"{name} (RMSE {np.sqrt(np.mean(d**2)):.2f} mm)",
        )
    ax.set_xlabel("marker error (mm)")
    ax.set_ylabel("count")
    integer_ticks(ax.yaxis)
    ax.legend()
    ax.grid(True, alpha=0.3)
    return _save(fig, path)
