"""Figures of simulated motions: an animation of the backbone and the tip position over time.

Matplotlib only (Agg canvas, no pyplot state); GIFs are written with matplotlib's Pillow writer
(Pillow is a dependency of matplotlib), MP4 with ffmpeg when it is installed.
"""

from __future__ import annotations

import os

import numpy as np
from matplotlib.animation import FFMpegWriter, FuncAnimation, PillowWriter
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .._dynamics.simulate import Trajectory
from .._model.query import tip_pose
from .._model.scene import Scene
from .equilibria import Drawn, arrow_length, draw_backbone, set_limits

__all__ = ["animate_trajectory", "plot_tip_trajectory", "tip_positions"]


def tip_positions(scene: Scene, trajectory: Trajectory) -> np.ndarray:
    """Tip positions (k, 3) in metres at the trajectory's save times."""
    return np.stack([np.asarray(tip_pose(scene, q)[0]) for q in np.asarray(trajectory.q)])


def plot_tip_trajectory(
    scene: Scene, trajectory: Trajectory, path=None, *, title: str | None = None
) -> Figure:
    """Tip position (x, y, z in mm) against time (s), one panel per axis."""
    ts = np.asarray(trajectory.ts)
    tip = 1e3 * tip_positions(scene, trajectory)
    fig = Figure(figsize=(7.5, 6.5), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(3, 1, sharex=True)
    for k, (ax, name) in enumerate(zip(axes, "xyz", strict=True)):
        ax.plot(ts, tip[:, k], color="#1f77b4", lw=2)
        ax.axhline(tip[-1, k], color="0.6", lw=0.8, ls="--")
        ax.set_ylabel(f"tip {name} (mm)")
        ax.grid(True, color="0.9")
    axes[-1].set_xlabel("time (s)")
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
    qs = np.asarray(trajectory.q)
    ts = np.asarray(trajectory.ts)
    drawn = [Drawn(scene, q) for q in qs]
    arrow_mm = arrow_length(drawn)
    pts = np.concatenate([d.extent_points(arrow_mm) for d in drawn])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    tips = np.stack([d.points[-1] for d in drawn])

    fig = Figure(figsize=(4.4 * len(views), 4.8), layout="constrained")
    FigureCanvasAgg(fig)
    axes = [
        fig.add_subplot(1, len(views), i + 1, **({"projection": "3d"} if v == "3d" else {}))
        for i, v in enumerate(views)
    ]

    def draw(k):
        for ax, view in zip(axes, views, strict=True):
            ax.clear()
            draw_backbone(ax, drawn[k], view=view, arrow_mm=arrow_mm, load_labels=False)
            if view == "3d":
                ax.plot(tips[: k + 1, 0], tips[: k + 1, 1], tips[: k + 1, 2], color="0.5", lw=1)
            else:
                i, j = {"xz": (0, 2), "yz": (1, 2), "xy": (0, 1)}[view]
                ax.plot(tips[: k + 1, i], tips[: k + 1, j], color="0.5", lw=1)
            set_limits(ax, view, lo, hi)
        fig.suptitle(f"{title + ': ' if title else ''}t = {ts[k]:.3f} s")
        return []

    anim = FuncAnimation(fig, draw, frames=len(drawn), blit=False)
    writer = PillowWriter(fps=fps) if ext == ".gif" else FFMpegWriter(fps=fps)
    anim.save(path, writer=writer, dpi=80)
