"""Axis ticks a printed figure can use: whole numbers on count axes, plain numbers on log axes
(``0.2``, ``1``, ``50``; never ``2x10^0``)."""

from __future__ import annotations

import numpy as np
from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullFormatter

__all__ = ["integer_ticks", "plain_log_ticks"]


def integer_ticks(axis) -> None:
    """Ticks at whole numbers only (counts, iterations) on ``axis`` (``ax.xaxis``/``ax.yaxis``)."""
    axis.set_major_locator(MaxNLocator(integer=True))


def _plain(value: float, _pos=None) -> str:
    """A positive number as written by hand: ``0.002``, ``0.5``, ``20``; ``1e-05`` and
    ``3e+06`` beyond."""
    if value <= 0 or not np.isfinite(value):
        return ""
    return f"{value:.6g}"


def plain_log_ticks(axis, low: float, high: float) -> None:
    """Ticks on a log ``axis`` spanning ``low..high`` (> 0) labelled as plain numbers: at every
    digit within one decade, at 1, 2 and 5 of each decade over up to two, at every decade beyond
    (and evenly spaced ones where that leaves fewer than two); minor ticks unlabelled."""
    decades = np.log10(max(high, low) / min(high, low)) if low > 0 and high > 0 else np.inf
    subs = np.arange(1.0, 10.0) if decades <= 1 else (1.0, 2.0, 5.0) if decades <= 2 else (1.0,)
    axis.set_major_locator(LogLocator(base=10.0, subs=subs, numticks=12))
    axis.set_major_formatter(FuncFormatter(_plain))
    axis.set_minor_formatter(NullFormatter())
