"""Figures of simulated motions: an animation of the backbone and the tip position over time.

Matplotlib only (Agg canvas, no pyplot state); GIFs are written with matplotlib's Pillow writer
(Pillow is a dependency of matplotlib), MP4 with ffmpeg when it is installed.
"""

from __future__ import annotations

import os

import matplotlib
import numpy as np
from matplotlib.animation import FFMpegWriter, PillowWriter
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .._dynamics.simulate import Trajectory
from .._model.query import tip_pose
from .._model.scene import Scene
from .drawn import Drawn
from .equilibria import (
    CASE_COLORS,
    VIEW_TITLES,
    VIEWS,
    arrow_length,
    draw_backbone,
    set_limits,
)

__all__ = ["animate_trajectory", "plot_tip_trajectory", "tip_positions"]

_TIP_SAMPLES = 400  # points of the tip curve from the dense output: smooth at any duration


def tip_positions(scene: Scene, trajectory: Trajectory) -> np.ndarray:
    """Tip positions (k, 3) in metres at the trajectory's save times."""
    return _tips(scene, np.asarray(trajectory.q))


def _tips(scene: Scene, qs: np.ndarray) -> np.ndarray:
    return np.stack([np.asarray(tip_pose(scene, q)[0]) for q in qs])


def _tip_curve(scene: Scene, trajectory: Trajectory, n_points: int):
    """``(times, tip positions in m)``: ``n_points`` from the solver's dense output when the
    trajectory kept it and reached its end, else the save times."""
    ts = np.asarray(trajectory.ts)
    if trajectory.solution is None or not bool(trajectory.successful):
        return ts, tip_positions(scene, trajectory)
    times = np.linspace(ts[0], ts[-1], n_points)
    qs, _ = trajectory.evaluate(times)
    return times, _tips(scene, np.asarray(qs))


def plot_tip_trajectory(
    scene: Scene,
    trajectory: Trajectory,
    path=None,
    *,
    title: str | None = None,
    equilibrium=None,
    n_points: int = _TIP_SAMPLES,
) -> Figure:
    """Tip position (x, y, z in mm) against time (s), one panel per axis.

    The curve is sampled at ``n_points`` times from the solver's dense output when the
    trajectory has one (``pacjax.simulate(..., dense=True)``), else drawn through the save
    times. ``equilibrium``: a configuration (or Equilibrium) the motion should settle on, e.g.
    the static equilibrium under the same commands, drawn as a dashed line.
    """
    times, tip = _tip_curve(scene, trajectory, n_points)
    tip = 1e3 * tip
    settled = None
    if equilibrium is not None:
        settled = 1e3 * np.asarray(tip_pose(scene, getattr(equilibrium, "q", equilibrium))[0])
    fig = Figure(figsize=(7.5, 6.5), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(3, 1, sharex=True)
    for k, (ax, name) in enumerate(zip(axes, "xyz", strict=True)):
        ax.plot(times, tip[:, k], color=CASE_COLORS[0], lw=2, label="simulated tip")
        if settled is not None:
            ax.axhline(
                settled[k], color="0.4", lw=1.0, ls="--", label="static equilibrium, same commands"
            )
        ax.set_ylabel(f"tip {name} (mm)")
        ax.grid(True, color="0.9")
    axes[0].legend(loc="best", fontsize=9)
    axes[-1].set_xlabel("time (s)")
    axes[-1].set_xlim(times[0], times[-1])
    if title:
        fig.suptitle(title)
    if path is not None:
        fig.savefig(os.fspath(path), dpi=110)
    return fig


def animate_trajectory(
    scene: Scene,
    trajectory: Trajectory,
    path,
    *,
    fps: int = 20,
    title: str | None = None,
    views=("3d", "xz"),
) -> None:
    """Write an animation (``.gif`` with Pillow, ``.mp4`` with ffmpeg) of the backbone, one
    frame per save time of ``trajectory``, drawn at a fixed scale, with the tip's path."""
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in (".gif", ".mp4"):
        raise ValueError(f"animation path must end in .gif or .mp4, got {path!r}")
    if fps < 1:
        raise ValueError(f"fps must be >= 1, got {fps}")
    fig, draw, n_frames = animation_frames(scene, trajectory, title=title, views=views)
    writer = PillowWriter(fps=fps) if ext == ".gif" else FFMpegWriter(fps=fps)
    write_frames(fig, draw, n_frames, writer, path, dpi=80)


def write_frames(fig: Figure, draw, n_frames: int, writer, path, dpi: int) -> None:
    """Draw frames ``0 .. n_frames - 1`` and hand each to ``writer`` (a matplotlib movie
    writer), drawing the figure once a frame.

    The panels' limits are the whole motion's (:func:`animation_frames`), so the first frame's
    constrained layout is every frame's: it is computed once and then held. (Not matplotlib's
    ``FuncAnimation``: on an Agg canvas it draws each frame three times and lays it out
    twice.)"""
    with writer.saving(fig, os.fspath(path), dpi):
        for k in range(n_frames):
            draw(k)
            writer.grab_frame()
            if k == 0:
                # No engine at all: a figure with one (even "none"'s placeholder) is drawn
                # twice by each savefig.
                with matplotlib.rc_context(
                    {"figure.autolayout": False, "figure.constrained_layout.use": False}
                ):
                    fig.set_layout_engine(None)


def animation_frames(scene: Scene, trajectory: Trajectory, *, title=None, views=("3d", "xz")):
    """``(figure, draw, n_frames)`` of :func:`animate_trajectory`: ``draw(k)`` draws the
    backbone at save time ``k`` on the figure's panels (one per view, titled, side by side)."""
    qs = np.asarray(trajectory.q)
    ts = np.asarray(trajectory.ts)
    drawn = [Drawn(scene, q) for q in qs]
    arrow_mm = arrow_length(drawn)
    pts = np.concatenate([d.extent_points(arrow_mm) for d in drawn])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    tips = np.stack([d.points[-1] for d in drawn])

    fig = Figure(figsize=(4.6 * len(views), 4.8), layout="constrained")
    FigureCanvasAgg(fig)
    # Constrained layout does not see a 3D axes' z label: room for it between the panels.
    fig.get_layout_engine().set(wspace=0.12 if "3d" in views else 0.02)
    axes = [
        fig.add_subplot(1, len(views), i + 1, **({"projection": "3d"} if v == "3d" else {}))
        for i, v in enumerate(views)
    ]

    def draw(k):
        for ax, view in zip(axes, views, strict=True):
            ax.clear()
            draw_backbone(ax, drawn[k], view=view, arrow_mm=arrow_mm, load_labels=False)
            idx = (0, 1, 2) if view == "3d" else VIEWS[view]
            ax.plot(*[tips[: k + 1, i] for i in idx], color="0.5", lw=1)
            set_limits(ax, view, lo, hi)
            ax.set_title(VIEW_TITLES[view], fontsize=10)
        fig.suptitle(f"{title + ': ' if title else ''}t = {ts[k]:.3f} s")
        return []

    return fig, draw, len(drawn)
