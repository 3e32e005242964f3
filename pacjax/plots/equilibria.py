"""Figures of equilibria: the backbone in 3D and in two orthogonal projections, in mm.

Matplotlib only, drawn on :class:`matplotlib.figure.Figure` objects with the Agg canvas, so
nothing here touches pyplot's global state or the user's backend.

- :func:`draw_backbone` draws one configuration on one axes (3D, or a projection ``"xz"``,
  ``"yz"``, ``"xy"``): the body as a thick line with cross-section rings (a tube at the body's
  radius), the joints between segments, the tendons (shaded by tension when the controls are
  known), marker sites and the scene's payloads, forces and moments.
- :func:`plot_equilibria` draws several configurations (cases or models) overlaid: isometric 3D,
  front (x-z) and side (y-z) views with equal aspect, a legend and a colour bar of tendon
  tension.
- :func:`plot_equilibrium_grid` draws groups of overlaid cases side by side (one column per
  group, e.g. per tendon command), with shared scales.

Only the backbone takes its case's colour; markers, joints, loads and tendons look the same in
every case, so that the legend's one glyph for each is what every case shows. The legend lists
what the figure drew (:mod:`pacjax.plots.legend`).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import FancyArrowPatch

from .._model.scene import Scene
from .drawn import Drawn
from .legend import HANDLER_MAP, legend_entries
from .tendons import draw_tendons, tension_colorbar

__all__ = ["draw_backbone", "plot_equilibria", "plot_equilibrium_grid", "CASE_COLORS"]

#: Colours of successive cases (models, commands) in a figure.
CASE_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b")
#: Projections: the world axes (x, y, z = 0, 1, 2) each 2D view shows, and every view's title.
VIEWS = {"xz": (0, 2), "yz": (1, 2), "xy": (0, 1)}
VIEW_TITLES = {"3d": "3D view", "xz": "front (x-z)", "yz": "side (y-z)", "xy": "top (x-y)"}
_AXIS = "xyz"
_NEUTRAL = "0.2"  # loads, marker edges, joints: the same in every case
#: Legend order: the cases come first, then these, then anything else drawn.
_LEGEND_ORDER = (
    "base", "joint", "marker", "tendon", "slack tendon", "load", "moment", "point mass",
)  # fmt: skip


def _case_color(i: int) -> str:
    return CASE_COLORS[i % len(CASE_COLORS)]


def _case_style(i: int):
    """The first case solid, the others dashed on top of it, so that overlaps stay visible."""
    return "-" if i == 0 else (0, (3.5, 1.8))


def _as_cases(scene: Scene, equilibria, controls=None) -> dict[str, tuple]:
    """Normalise ``{label: q | Equilibrium | (scene, q) | (scene, q, controls)}`` or a list of
    them into ``{label: (scene, q, controls)}`` (``controls`` the default)."""
    if not isinstance(equilibria, Mapping):
        if not isinstance(equilibria, Sequence) or isinstance(equilibria, (str, bytes)):
            equilibria = [equilibria]
        equilibria = {f"case {i}": e for i, e in enumerate(equilibria)}
    cases = {}
    for label, value in equilibria.items():
        case_scene, case_controls = scene, controls
        if isinstance(value, tuple) and len(value) in (2, 3) and isinstance(value[0], Scene):
            case_scene, value, *rest = value
            case_controls = rest[0] if rest else controls
        q = getattr(value, "q", value)
        if case_scene is None:
            raise ValueError(f"case {label!r}: no scene given for it")
        cases[str(label)] = (case_scene, np.asarray(q, float), case_controls)
    if not cases:
        raise ValueError("nothing to plot: no equilibria given")
    return cases


def arrow_length(drawn: Sequence[Drawn]) -> float:
    """Arrow length (mm) for loads: a fifth of the longest robot."""
    return 0.2 * max(float(np.ptp(d.points, axis=0).max() or 1.0) for d in drawn) or 50.0


def largest_tension(drawn: Sequence[Drawn]) -> float:
    """The largest tendon tension (N) among ``drawn`` (0 when none is known): the top of the
    shared shade scale."""
    known = [d.tensions for d in drawn if d.tensions is not None and d.tensions.size]
    return float(max(np.max(t) for t in known)) if known else 0.0


# ------------------------------------------------------------------------------ drawing
def draw_backbone(
    ax,
    scene: Scene | Drawn,
    q=None,
    *,
    controls=None,
    view: str = "3d",
    color: str = CASE_COLORS[0],
    label: str | None = None,
    linestyle="-",
    markers: bool = True,
    rings: bool = True,
    tendons: bool = True,
    loads: bool = True,
    load_labels: bool = True,
    arrow_mm: float | None = None,
    tension_scale: float | None = None,
):
    """Draw one configuration on ``ax`` (positions in mm). Every artist worth a legend entry
    carries a label (``label`` on the backbone), so ``ax.legend()`` lists what was drawn.

    Args:
        ax: a 3D axes (``view="3d"``) or a 2D axes for the projection ``view`` (``"xz"``,
            ``"yz"`` or ``"xy"``).
        scene: the :class:`Scene` (or an already evaluated drawing, internal).
        q: configuration of ``scene``.
        controls: the scene's controls (one per tendon): tendons shaded by their tension.
        color, label, linestyle: the case's colour, legend label and backbone line style.
        markers: draw the scene's marker sites; ``rings``: draw cross-section rings at the
            body's radius (tube look); ``tendons``: draw the tendons along the body;
            ``loads``: draw payload, force and moment arrows; ``load_labels``: write their
            magnitudes (once per panel is enough).
        arrow_mm: arrow length (mm) for loads (default: a fifth of the robot).
        tension_scale: tension (N) drawn darkest (default: this configuration's largest).
    """
    d = scene if isinstance(scene, Drawn) else Drawn(scene, q, controls)
    if view != "3d" and view not in VIEWS:
        raise ValueError(f"view must be '3d' or one of {tuple(VIEWS)}, got {view!r}")
    idx = (0, 1, 2) if view == "3d" else VIEWS[view]
    arrow_mm = arrow_length([d]) if arrow_mm is None else arrow_mm
    if rings and np.any(d.radius > 0):
        _draw_rings(ax, d, idx, color)
    # A joint under a marker site, or a light mass under either, the base or another load,
    # would be listed but not seen: it is left out.
    hidden = d.markers if markers and d.markers is not None else np.zeros((0, 3))
    others = [p[None] for kind, p, *_ in d.loads if kind != "mass"]
    hidden = np.concatenate(
        [hidden, _draw_body(ax, d, idx, color, label, linestyle, hidden), *others]
    )
    if tendons and d.tendon_paths:
        scale = largest_tension([d]) if tension_scale is None else tension_scale
        draw_tendons(ax, d.tendon_paths, d.tensions, idx, scale)
    if markers and d.markers is not None:
        _hollow_points(ax, _project(d.markers, idx), "o", 5.5, "marker", zorder=5)
    if loads:
        _draw_loads(ax, d, idx, arrow_mm, load_labels, hidden)
    return d


def _project(p, idx) -> list[np.ndarray]:
    """The coordinates ``idx`` of a point (3,) or points (n, 3): what ``ax.plot`` takes."""
    p = np.atleast_2d(p)
    return [p[:, i] for i in idx]


def _draw_rings(ax, d: Drawn, idx, color) -> None:
    """Cross-section rings: the base ring dark and thick, segment ends in the case's colour,
    the others faint (so that the tube reads as a tube without hiding the backbone). The rings
    of one style are one line, broken between rings (a row of NaN), so that an animation
    frame, which draws them anew, has three artists of them rather than one a ring."""
    styles = {
        "base": dict(color="0.25", lw=2.2, alpha=0.9),
        "end": dict(color=color, lw=1.0, alpha=0.7),
        "faint": dict(color="0.55", lw=0.5, alpha=0.3),
    }
    rings = {name: [] for name in styles}
    for i in d.ring_index:
        name = "base" if i == 0 else ("end" if i in d.boundary_index else "faint")
        rings[name] += [d.ring(i), np.full((1, 3), np.nan)]
    for name, parts in rings.items():
        if parts:
            ax.plot(*_project(np.concatenate(parts[:-1]), idx), zorder=1, **styles[name])


def _hollow_points(ax, coordinates, marker: str, size: float, label: str, zorder: int) -> None:
    """Points drawn as white glyphs with a dark edge (markers, joints): the same in every case,
    so that one legend entry stands for all of them."""
    ax.plot(
        *coordinates,
        ls="none",
        marker=marker,
        ms=size,
        mfc="white",
        mec=_NEUTRAL,
        mew=1.2,
        label=label,
        zorder=zorder,
    )


def _square(ax, coordinates, size: float, color: str, label: str, zorder: int) -> None:
    """A filled grey square (the base, a light point mass)."""
    ax.plot(*coordinates, ls="none", marker="s", ms=size, color=color, label=label, zorder=zorder)


def _visible(points: np.ndarray, hidden: np.ndarray) -> np.ndarray:
    """Which of ``points`` (k, 3) lie off every point of ``hidden`` (mm)."""
    if not len(hidden) or not len(points):
        return np.ones(len(points), bool)
    gap = np.linalg.norm(points[:, None] - hidden[None], axis=-1).min(axis=1)
    return gap > 1e-6


def _draw_body(ax, d: Drawn, idx, color, label, linestyle, hidden) -> np.ndarray:
    """The backbone (a faint wide halo under the line), the joints (those not under a point of
    ``hidden``) and the base; returns the points (mm) of the joints and base drawn."""
    solid = linestyle in ("-", "solid")
    points = _project(d.points, idx)
    ax.plot(*points, color=color, lw=8, alpha=0.15, solid_capstyle="round", zorder=2)
    ax.plot(
        *points,
        color=color,
        lw=3.0 if solid else 2.2,
        ls=linestyle,
        label=label,
        solid_capstyle="round",
        zorder=3,
    )
    joints = d.points[d.joint_index]
    joints = joints[_visible(joints, hidden)]
    if len(joints):
        _hollow_points(ax, _project(joints, idx), "D", 5, "joint", zorder=4)
    _square(ax, _project(d.points[0], idx), 8, "0.3", "base", zorder=4)
    return np.concatenate([joints, d.points[:1]])


def _draw_loads(ax, d: Drawn, idx, arrow_mm: float, load_labels: bool, hidden) -> None:
    """Light point masses as small squares (those not under a point of ``hidden``), moments as
    a circular arrow, weights and forces as arrows of length ``arrow_mm``, all in one dark grey
    (their labels tell them apart)."""
    for kind, p, direction, text in d.loads:
        if kind == "mass":
            if not _visible(p[None], hidden)[0]:
                continue
            _square(ax, _project(p, idx), 3.5, "0.35", "point mass", zorder=5)
        elif kind == "moment":
            ax.plot(
                *_project(p, idx),
                ls="none",
                marker="$\\circlearrowleft$",
                ms=14,
                color=_NEUTRAL,
                label="moment",
            )
            if load_labels:
                _label(ax, _project(p, idx), text)
        else:
            _arrow(ax, p, p + arrow_mm * direction, idx, _NEUTRAL)
            if load_labels:
                _label(ax, _project(p + arrow_mm * direction, idx), text)


def _arrow(ax, start, end, idx, color):
    if len(idx) == 3:
        delta = end - start
        ax.quiver(
            *start, *delta, color=color, lw=2, arrow_length_ratio=0.25, label="load", zorder=6
        )
    else:
        start, end = (start[idx[0]], start[idx[1]]), (end[idx[0]], end[idx[1]])
        arrow = FancyArrowPatch(
            start, end, arrowstyle="-|>", color=color, lw=2, mutation_scale=14, zorder=6
        )
        ax.add_patch(arrow).set_label("load")


def _label(ax, coords, text):
    if not text:
        return
    coords = [float(c[0]) for c in coords]
    ax.text(*coords, " " + text, color="0.15", fontsize=8, zorder=7)


def _draw_targets(ax, targets, view):
    idx = (0, 1, 2) if view == "3d" else VIEWS[view]
    for i, (label, pts) in enumerate(targets.items()):
        pts = 1e3 * np.atleast_2d(np.asarray(pts, float))
        ax.plot(
            *[pts[:, j] for j in idx],
            ls="none",
            marker="x" if i == 0 else "+",
            ms=9,
            mew=2,
            color="black",
            label=label,
            zorder=8,
        )


def set_limits(ax, view: str, lo: np.ndarray, hi: np.ndarray):
    """Equal scales on every axis, around the box ``lo..hi`` (mm)."""
    center = 0.5 * (lo + hi)
    half = 0.55 * float(np.max(hi - lo)) or 50.0
    if view == "3d":
        ax.set_xlim(center[0] - half, center[0] + half)
        ax.set_ylim(center[1] - half, center[1] + half)
        ax.set_zlim(center[2] - half, center[2] + half)
        ax.set_box_aspect((1, 1, 1), zoom=1.1)
        ax.set_xlabel("x (mm)", labelpad=-2)
        ax.set_ylabel("y (mm)", labelpad=-2)
        ax.set_zlabel("z (mm)", labelpad=-2)
        ax.tick_params(labelsize=7, pad=0)
        ax.view_init(elev=22, azim=-55)
    else:
        i, j = VIEWS[view]
        ax.set_xlim(center[i] - half, center[i] + half)
        ax.set_ylim(center[j] - half, center[j] + half)
        ax.set_aspect("equal")
        ax.set_xlabel(f"{_AXIS[i]} (mm)")
        ax.set_ylabel(f"{_AXIS[j]} (mm)")
        ax.tick_params(labelsize=8)
        ax.grid(True, color="0.9", lw=0.8)
        ax.set_axisbelow(True)


def _normalise_targets(targets):
    if targets is None:
        return {}
    if isinstance(targets, Mapping):
        return dict(targets)
    return {"target": targets}


def _legend(fig, axes, cases: Sequence[str]):
    """One legend under the panels: the cases, then every kind of thing drawn, each glyph
    copied from an artist in the figure."""
    handles, labels = legend_entries(axes, first=[*cases, *_LEGEND_ORDER])
    fig.legend(
        handles,
        labels,
        handler_map=HANDLER_MAP,
        loc="lower center",
        ncol=min(len(handles), 8),
        frameon=False,
        fontsize=10,
        bbox_to_anchor=(0.5, 0.0),
    )


def plot_equilibrium_grid(
    groups: Mapping[str, Mapping],
    path=None,
    *,
    title: str | None = None,
    scene: Scene | None = None,
    controls=None,
    markers: bool = True,
    targets=None,
    views: Sequence[str] = ("3d", "xz", "yz"),
) -> Figure:
    """Groups of overlaid equilibria side by side: one column per group, one row per view,
    all panels at the same scale.

    Args:
        groups: ``{group title: {case label: q | Equilibrium | (scene, q) | (scene, q,
            controls)}}``; the same case label in every group gets the same colour (e.g. one
            colour per model).
        path: where to save the figure (PNG, PDF, ... by extension); None: only return it.
        title: figure title.
        scene: the scene of cases given as a bare ``q`` or Equilibrium.
        controls: the controls of cases given without their own: with them, the tendons are
            shaded by tension, with a colour bar in N.
        markers: draw marker sites.
        targets: points (m, 3) in metres, or ``{label: points}``, drawn in every panel.
        views: rows, among ``"3d"``, ``"xz"``, ``"yz"``, ``"xy"``.

    Returns:
        The :class:`matplotlib.figure.Figure`.
    """
    for view in views:
        if view != "3d" and view not in VIEWS:
            raise ValueError(f"views must be '3d' or among {tuple(VIEWS)}, got {view!r}")
    drawn = {
        g: {k: Drawn(*v) for k, v in _as_cases(scene, c, controls).items()}
        for g, c in groups.items()
    }
    if not drawn:
        raise ValueError("nothing to plot: no groups given")
    labels: list[str] = []
    for cases in drawn.values():
        labels += [k for k in cases if k not in labels]
    everything = [d for cases in drawn.values() for d in cases.values()]
    targets = _normalise_targets(targets)
    arrow_mm = arrow_length(everything)

    single = len(drawn) == 1  # one group: the views side by side
    tension_scale = largest_tension(everything)
    fig = _panel_figure(
        drawn,
        views,
        {k: i for i, k in enumerate(labels)},
        markers=markers,
        targets=targets,
        arrow_mm=arrow_mm,
        box=_bounding_box(everything, targets, arrow_mm),
        tension_scale=tension_scale,
    )
    if title:
        fig.suptitle(title, fontsize=14)
    panels = list(fig.axes)
    if tension_scale > 0:
        tension_colorbar(fig, panels, tension_scale)
    _legend(fig, panels, [*labels, *targets])
    # Constrained layout does not see a 3D axes' z label: leave room for it explicitly.
    fig.get_layout_engine().set(
        rect=(0, 0.06 if single else 0.035, 1, 0.96), wspace=0.08 if "3d" in views else 0.02
    )
    if path is not None:
        fig.savefig(os.fspath(path), dpi=110)
    return fig


def _bounding_box(everything: Sequence[Drawn], targets: Mapping, arrow_mm: float):
    """``(lo, hi)`` (mm) around every body, load arrow and target, so that all panels share one
    scale."""
    pts = [d.extent_points(arrow_mm) for d in everything]
    pts += [1e3 * np.atleast_2d(np.asarray(t, float)) for t in targets.values()]
    pts = np.concatenate(pts)
    return pts.min(axis=0), pts.max(axis=0)


def _panel_figure(drawn, views, order, *, markers, targets, arrow_mm, box, tension_scale):
    """A figure of one panel per group x view, each case coloured by its place in ``order``;
    titles: the groups over the columns and the views down the first, or, for one group, its
    views side by side under their names."""
    single = len(drawn) == 1
    n_cols, n_rows = (len(views), 1) if single else (len(drawn), len(views))
    fig = Figure(figsize=(4.4 * n_cols + 0.4, 4.2 * n_rows + 1.4), layout="constrained")
    FigureCanvasAgg(fig)
    for col, (group, cases) in enumerate(drawn.items()):
        for row, view in enumerate(views):
            index = row + 1 if single else row * n_cols + col + 1
            kw = {"projection": "3d"} if view == "3d" else {}
            ax = fig.add_subplot(n_rows, n_cols, index, **kw)
            for j, (label, d) in enumerate(cases.items()):
                draw_backbone(
                    ax,
                    d,
                    view=view,
                    color=_case_color(order[label]),
                    label=label,
                    linestyle=_case_style(order[label]),
                    markers=markers,
                    load_labels=j == 0,
                    arrow_mm=arrow_mm,
                    tension_scale=tension_scale,
                )
            _draw_targets(ax, targets, view)
            set_limits(ax, view, *box)
            if single:
                ax.set_title(VIEW_TITLES[view], fontsize=11)
            elif row == 0:
                ax.set_title(group, fontsize=12, fontweight="bold")
            elif col == 0:
                ax.set_title(VIEW_TITLES[view], fontsize=10, loc="left", color="0.3")
    return fig


def plot_equilibria(
    scene: Scene | None,
    equilibria,
    path=None,
    *,
    title: str | None = None,
    controls=None,
    markers: bool = True,
    targets=None,
    views: Sequence[str] = ("3d", "xz", "yz"),
) -> Figure:
    """Several equilibria overlaid: isometric 3D, front (x-z) and side (y-z) views, in mm.

    Args:
        scene: the :class:`Scene` the configurations belong to (None when every case carries
            its own scene, e.g. comparing models).
        equilibria: ``{label: q | Equilibrium | (scene, q) | (scene, q, controls)}``, a list of
            them, or one.
        path: where to save the figure; None: only return it.
        title: figure title.
        controls: the controls of cases given without their own: with them, the tendons are
            shaded by tension, with a colour bar in N.
        markers: draw the scene's marker sites.
        targets: points (m, 3) in metres, or ``{label: points}`` (e.g. measured markers).
        views: panels, among ``"3d"``, ``"xz"``, ``"yz"``, ``"xy"``.

    Returns:
        The :class:`matplotlib.figure.Figure`.
    """
    return plot_equilibrium_grid(
        {"": _as_cases(scene, equilibria, controls)},
        path,
        title=title,
        markers=markers,
        targets=targets,
        views=views,
    )
