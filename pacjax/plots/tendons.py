"""Tendons in figures: where each tendon runs along the body, and its tension as a shade.

- :func:`tendon_sites` gives the points of one tendon's path as sites ``(segment, s,
  offset in the cross-section frame)``, so that one kinematics call places them in the world:
  the guide holes of a ring-routed tendon (its length is the sum of the straight chords between
  them, so straight lines between them are the tendon), or points along a channel (offset and
  angle linear in the route coordinate, as in :mod:`pacjax._model.channels`).
- :func:`draw_tendons` draws them on one axes: a taut tendon shaded and widened by its tension
  (:data:`TENSION_CMAP`, light to dark), a slack one dotted, and, without controls, all in one
  neutral grey; :func:`tension_colorbar` adds the colour bar (N).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib import colormaps
from matplotlib.cm import ScalarMappable
from matplotlib.colors import ListedColormap, Normalize

from .._model.tendons import Tendon

__all__ = ["TENSION_CMAP", "draw_tendons", "tendon_sites", "tension_colorbar"]

#: Tension shades: light grey (no tension) to black (the largest in the figure). Grey keeps
#: clear of the case colours of the backbones and prints in black and white.
TENSION_CMAP = ListedColormap(colormaps["Greys"](np.linspace(0.3, 1.0, 256)), name="tension")
_CHANNEL_POINTS = 16  # path samples per segment of a channel (a curve between the frames)
_NO_TENSION = dict(color="0.45", ls="-", lw=1.2, label="tendon")
_SLACK = dict(color="0.6", ls=":", lw=1.0, label="slack tendon")


def tendon_sites(tendon: Tendon) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(segments, s, offsets)`` of points along ``tendon`` from its entry to its anchor:
    ``offsets`` (k, 3) in metres in the cross-section frame at ``(segments[i], s[i])``."""
    if tendon.routing == "rings":
        sites = tendon.route()
    else:
        sites = []
        for k in range(tendon.entry_segment, tendon.segment + 1):
            end = tendon.s if k == tendon.segment else 1.0
            # The end of one segment is the start of the next: each point once.
            start = 0 if k == tendon.entry_segment else 1
            sites += [(k, float(s)) for s in np.linspace(0.0, end, _CHANNEL_POINTS)[start:]]
    frac = np.array([tendon.route_fraction(k, s) for k, s in sites])
    r0, r1 = float(np.asarray(tendon.offset)), float(np.asarray(tendon.anchor_offset))
    a0, a1 = float(np.asarray(tendon.angle)), float(np.asarray(tendon.anchor_angle))
    radius = r0 + (r1 - r0) * frac
    angle = a0 + (a1 - a0) * frac
    offsets = np.stack([radius * np.cos(angle), radius * np.sin(angle), np.zeros_like(frac)], -1)
    segments = np.array([k for k, _ in sites], np.int32)
    return segments, np.array([s for _, s in sites], float), offsets


def _style(tension: float | None, largest: float) -> dict:
    if tension is None:
        return _NO_TENSION
    if tension <= 0.0 or largest <= 0.0:
        return _SLACK
    share = min(tension / largest, 1.0)
    return dict(color=TENSION_CMAP(share), ls="-", lw=0.8 + 1.4 * share, label="tendon")


def draw_tendons(
    ax, paths: Sequence[np.ndarray], tensions, idx: Sequence[int], largest: float
) -> None:
    """Draw tendon paths (each (k, 3), mm) on ``ax`` (coordinates ``idx``: three for a 3D
    axes), shaded by ``tensions`` (N, None: unknown) on the scale ``0..largest`` N."""
    if tensions is None:
        tensions = [None] * len(paths)
    for path, tension in zip(paths, tensions, strict=True):
        ax.plot(
            *[path[:, i] for i in idx],
            solid_capstyle="round",
            zorder=2.5,  # over the backbone's halo, under its line: the body stays in view
            **_style(tension, largest),
        )


def tension_colorbar(fig, axes, largest: float):
    """A colour bar of tendon tension (N), ``0..largest``, beside ``axes``."""
    mappable = ScalarMappable(Normalize(0.0, largest), TENSION_CMAP)
    bar = fig.colorbar(mappable, ax=axes, shrink=0.6, aspect=25, pad=0.02)
    bar.set_label("tendon tension (N)")
    return bar
