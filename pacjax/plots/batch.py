"""Figure of a batch: the tip positions of its rows in three views (x-y, x-z, y-z, mm).

Matplotlib on a :class:`~matplotlib.figure.Figure` with the Agg canvas (no pyplot state).
"""

from __future__ import annotations

import os

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .equilibria import CASE_COLORS

__all__ = ["plot_workspace"]


def plot_workspace(
    tip, converged, path=None, *, title: str | None = None, n_rows: int | None = None
) -> Figure:
    """Tip positions (k, 3) in metres, converged rows as blue dots and the others as red
    crosses, in three views with equal scales.

    Args:
        tip: tip positions (k, 3), m.
        converged: (k,) whether each row's solve converged.
        path: where to save the figure; None: only return it.
        title: figure title (before ``tip workspace``).
        n_rows: rows in the batch when ``tip`` holds a subset of them (for the title).
    """
    tip = 1e3 * np.asarray(tip, float)
    ok = np.asarray(converged, bool)
    n_rows = len(tip) if n_rows is None else n_rows
    fig = Figure(figsize=(15, 5.4), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 3)
    size = 4 if len(tip) > 2000 else 12
    for ax, (i, j) in zip(axes, ((0, 1), (0, 2), (1, 2)), strict=True):
        ax.scatter(
            tip[ok, i],
            tip[ok, j],
            s=size,
            c=CASE_COLORS[0],
            alpha=0.5,
            lw=0,
            label=f"converged ({int(ok.sum())})",
        )
        if (~ok).any():
            ax.scatter(
                tip[~ok, i],
                tip[~ok, j],
                s=3 * size,
                c=CASE_COLORS[1],
                marker="x",
                label=f"not converged ({int((~ok).sum())})",
            )
        ax.set_xlabel(f"{'xyz'[i]} (mm)")
        ax.set_ylabel(f"{'xyz'[j]} (mm)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    # Glyphs as large as a reader can see; colour and marker those of the points.
    axes[0].legend(loc="best", fontsize=9, markerscale=max(1.0, 30.0 / size) ** 0.5)
    shown = f"{len(tip)} of {n_rows} rows" if len(tip) < n_rows else f"{n_rows} rows"
    fig.suptitle((title + ": " if title else "") + f"tip workspace ({shown})")
    if path is not None:
        fig.savefig(os.fspath(path), dpi=120)
    return fig
