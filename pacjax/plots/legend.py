"""Legends built from the artists a figure draws, so that every entry looks like what it names
and nothing absent is listed.

Drawing functions give each artist worth a legend entry a label (the backbone its case's name,
a marker site ``"marker"``); :func:`legend_entries` collects them from the axes, one entry per
label, the legend glyph copied from the first artist drawn with it. Load arrows (a
:class:`~matplotlib.patches.FancyArrowPatch` in 2D, a quiver in 3D) get an arrow glyph in their
colour (:data:`HANDLER_MAP`).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.legend_handler import HandlerBase
from matplotlib.patches import FancyArrow, FancyArrowPatch

__all__ = ["HANDLER_MAP", "legend_entries"]


class _ArrowHandler(HandlerBase):
    """A horizontal arrow in the colour of the arrow it stands for."""

    def create_artists(
        self, legend, orig_handle, xdescent, ydescent, width, height, fontsize, trans
    ):
        color = orig_handle.get_edgecolor()
        color = np.atleast_2d(color)[0] if np.ndim(color) else color
        arrow = FancyArrow(
            -xdescent,
            0.5 * height - ydescent,
            width,
            0.0,
            width=0.12 * height,
            head_width=0.6 * height,
            head_length=0.3 * width,
            length_includes_head=True,
            color=color,
            transform=trans,
        )
        return [arrow]


#: Legend handlers for the arrows (2D patches, 3D quivers), which the default ones draw as a
#: box or a plain line.
HANDLER_MAP = {FancyArrowPatch: _ArrowHandler(), LineCollection: _ArrowHandler()}


def legend_entries(axes: Iterable, first: Iterable[str] = ()) -> tuple[list, list[str]]:
    """``(handles, labels)`` of the labelled artists on ``axes``, one per label: the labels in
    ``first`` (those drawn) in that order, then the others in the order they were drawn."""
    found: dict[str, object] = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            found.setdefault(label, handle)
    labels = [x for x in first if x in found]
    labels += [x for x in found if x not in labels]
    return [found[x] for x in labels], labels
