"""The figures a paper would print: every legend entry looks like an artist drawn under its
name, count axes have whole-number ticks, log axes plain numbers, the simulated tip is a curve,
the animation's panels keep apart.

Inputs are built by hand (configurations, reports, trajectories) so that only the kinematics
compiles, not a solver.
"""

import io
from pathlib import Path
from types import SimpleNamespace

import jax.numpy as jnp
import matplotlib
import matplotlib.animation
import numpy as np
import pytest
from matplotlib.collections import Collection
from matplotlib.colors import to_rgba
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

import pacjax as pj
from pacjax.io.scenefile import load_scene
from pacjax.plots import animation, batch, equilibria
from pacjax.plots import fit as fitplots

matplotlib.use("Agg")

SCENES = Path(__file__).resolve().parent.parent / "experiments" / "scenes"


@pytest.fixture(scope="module")
def single():
    """One segment, three tendons in tension mode, markers at mid-length and tip."""
    scene, controls, _ = load_scene(SCENES / "tendon_single.toml")
    return scene, np.asarray(controls, float)


@pytest.fixture(scope="module")
def loaded():
    """Two segments (a joint), markers off the joint, length-mode tendons on rings and in a
    channel, and every kind of load the figures draw."""
    segment = pj.Segment(0.1, bending_stiffness=0.02, axial_stiffness=800.0, radius=0.012)
    tendons = [
        pj.Tendon(1, np.radians(90.0), 0.01, gain=500.0, guides=(0.0, 0.5, 1.0)),
        pj.Tendon(0, np.radians(210.0), 0.01, gain=500.0, routing="channel"),
    ]
    loads = [
        pj.Gravity(),
        pj.PointMass(0.1, 1, 1.0),
        pj.PointMass(0.01, 0, 0.5),
        pj.PointForce([0.3, 0.0, 0.0], 1, 0.5),
        pj.PointMoment([0.0, 0.0, 0.01], 0, 1.0),
    ]
    scene = pj.Scene(
        pj.Robot([segment, segment]),
        pj.PCC(),
        tendons=tendons,
        loads=loads,
        markers=[(0, 0.3), (1, 1.0)],
    )
    return scene, np.array([0.004, 0.0])


def _bent(scene, amount: float):
    """A bent configuration without a solve: every bending coordinate ``amount``, no
    elongation."""
    return np.array([0.0 if n.startswith("dL") else amount for n in scene.coordinate_names()])


# ------------------------------------------------------------------------------ checks
def _color(artist):
    if isinstance(artist, Line2D):
        return to_rgba(artist.get_color())
    if isinstance(artist, Collection):
        face = artist.get_facecolor()
        return tuple(face[0] if len(face) else artist.get_edgecolor()[0])
    return to_rgba(artist.get_facecolor())


def _style(artist) -> dict:
    """What a reader compares between a legend glyph and the drawing."""
    style = {"color": np.round(_color(artist), 3).tolist()}
    if isinstance(artist, Line2D):
        style |= {
            "marker": artist.get_marker(),
            "linestyle": artist.get_linestyle(),
            "face": np.round(to_rgba(artist.get_markerfacecolor()), 3).tolist(),
            "edge": np.round(to_rgba(artist.get_markeredgecolor()), 3).tolist(),
        }
    return style


def _drawn(fig, label: str) -> list:
    return [
        a
        for ax in fig.axes
        for a in ax.get_children()
        if isinstance(a, (Line2D, Collection, Patch)) and a.get_label() == label
    ]


def assert_legends_match(fig) -> int:
    """Every legend entry names artists drawn in ``fig`` and looks like one of them; returns
    how many entries were checked."""
    fig.canvas.draw()
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend()]
    assert legends, "no legend"
    checked = 0
    for legend in legends:
        for handle, text in zip(legend.legend_handles, legend.get_texts(), strict=True):
            label = text.get_text()
            drawn = _drawn(fig, label)
            assert drawn, f"legend entry {label!r}: nothing drawn under that name"
            styles = [_style(a) for a in drawn]
            assert _style(handle) in styles, f"{label!r}: legend {_style(handle)} vs {styles[0]}"
            checked += 1
    return checked


def _legend_labels(fig) -> list[str]:
    return [t.get_text() for legend in fig.legends for t in legend.get_texts()]


def _tick_numbers(labels) -> list[float]:
    texts = [t.get_text().replace("\N{MINUS SIGN}", "-") for t in labels]
    return [float(t) for t in texts if t]


# ------------------------------------------------------------------------------ equilibria
def test_solve_figure_draws_tendons_shaded_by_tension(single):
    scene, controls = single
    fig = equilibria.plot_equilibria(
        scene, {"PCC": _bent(scene, 0.3)}, controls=controls, title="solve"
    )
    assert assert_legends_match(fig) >= 4
    labels = _legend_labels(fig)
    # One segment: no joint; its tip marker covers the segment's end.
    assert "joint" not in labels and "segment end" not in labels
    assert {"PCC", "base", "marker", "tendon", "slack tendon"} <= set(labels)
    bars = [ax for ax in fig.axes if ax.get_ylabel() == "tendon tension (N)"]
    assert len(bars) == 1 and bars[0].get_ylim()[1] == pytest.approx(3.0)
    panel = fig.axes[1]  # front view: one line per tendon, the most pulled the darkest
    tendons = [a for a in panel.get_lines() if a.get_label() in ("tendon", "slack tendon")]
    assert len(tendons) == scene.n_tendons
    shade = [np.mean(to_rgba(a.get_color())[:3]) for a in tendons]
    assert shade[0] < shade[1] and tendons[2].get_linestyle() == ":"


def test_grid_figure_lists_what_each_case_draws(loaded):
    scene, controls = loaded
    groups = {
        "pull": {"PCC": (scene, _bent(scene, 0.2), controls), "PAC": _bent(scene, 0.25)},
        "slack": {"PCC": (scene, _bent(scene, 0.05), np.array([-0.02, -0.02]))},
    }
    fig = equilibria.plot_equilibrium_grid(groups, scene=scene, targets={"target": [[0, 0, 0.2]]})
    assert assert_legends_match(fig) >= 8
    labels = _legend_labels(fig)
    assert labels[:2] == ["PCC", "PAC"]
    for kind in ("joint", "marker", "tendon", "slack tendon", "load", "moment", "point mass"):
        assert kind in labels, kind
    # Without its controls, a case's tendons are drawn in the neutral tendon style.
    assert any(ax.get_ylabel() == "tendon tension (N)" for ax in fig.axes)


def test_inverse_figure_without_markers_lists_none(single):
    scene, controls = single
    cases = {f"target {i}": (scene, _bent(scene, 0.1 * i), controls * i) for i in (1, 2, 3)}
    fig = equilibria.plot_equilibria(
        scene,
        cases,
        markers=False,
        targets={"target": [[0.0, 0.01, 0.11]], "reached tip": [[0.0, 0.012, 0.11]]},
    )
    assert assert_legends_match(fig) >= 5
    labels = _legend_labels(fig)
    assert "marker" not in labels
    assert {"target 1", "target 3", "target", "reached tip"} <= set(labels)


# ------------------------------------------------------------------------------ identification
@pytest.fixture(scope="module")
def report(single):
    scene, _ = single
    rng = np.random.default_rng(0)
    qs = rng.normal(scale=0.2, size=(4, scene.n_dofs))

    def errors(noise):
        predicted = np.stack([np.asarray(pj.markers(scene, q)) for q in qs])
        measured = predicted + rng.normal(scale=noise, size=predicted.shape)
        return SimpleNamespace(q=qs, predicted=predicted, measured=measured)

    return SimpleNamespace(
        loss_history=[4.1, 2.3, 1.6, 1.2, 1.05, 1.01],  # inside one decade: "2x10^0" before
        rmse_history_mm=[30.0, 9.0, 2.0, 0.6, 0.31, 0.3],
        train=errors(2e-4),
        validation=errors(4e-4),
        rotation=np.eye(3),
        translation=np.zeros(3),
    )


def test_loss_plot_has_plain_log_ticks_and_whole_iterations(report):
    fig = fitplots.plot_loss(report)
    fig.canvas.draw()
    for ax in fig.axes:
        assert ax.get_yscale() == "log"
        texts = [t.get_text() for t in ax.get_yticklabels(which="both")]
        assert [t for t in texts if t], "no tick labels on the log axis"
        assert not [t for t in texts if "times" in t or "10^" in t], texts
        assert all(v.is_integer() for v in _tick_numbers(ax.get_xticklabels()))


def test_loss_plot_over_many_decades(report):
    wide = SimpleNamespace(**vars(report))
    wide.loss_history = list(np.geomspace(1e3, 1e-6, 12))
    wide.rmse_history_mm = list(np.geomspace(50.0, 0.1, 12))
    fig = fitplots.plot_loss(wide)
    fig.canvas.draw()
    texts = [t.get_text() for t in fig.axes[0].get_yticklabels(which="both")]
    assert len([t for t in texts if t]) >= 3
    assert not [t for t in texts if "times" in t or "10^" in t], texts


def test_error_histogram_counts_are_whole_numbers(report):
    fig = fitplots.plot_error_histogram(report)
    assert assert_legends_match(fig) == 2
    ticks = _tick_numbers(fig.axes[0].get_yticklabels())
    assert len(ticks) >= 2 and all(v.is_integer() for v in ticks), ticks


def test_backbones_legend_shows_line_and_crosses(single, report):
    scene, _ = single
    fig = fitplots.plot_backbones(scene, report)
    assert assert_legends_match(fig) == 4  # frames 0, 1, 2, 3


# ------------------------------------------------------------------------------ batch
def test_workspace_legend(tmp_path):
    rng = np.random.default_rng(1)
    tip = rng.normal(scale=0.05, size=(300, 3))
    converged = rng.random(300) > 0.1
    fig = batch.plot_workspace(tip, converged, tmp_path / "w.png", title="fake", n_rows=600)
    assert assert_legends_match(fig) == 2
    assert "300 of 600 rows" in fig._suptitle.get_text()
    assert (tmp_path / "w.png").stat().st_size > 0


# ------------------------------------------------------------------------------ dynamics
class _Motion:
    """A dense output: every coordinate a damped oscillation (diffrax's ``evaluate``)."""

    def __init__(self, n_dofs: int):
        self.n = n_dofs

    def evaluate(self, t):
        q = 0.3 * (1.0 - jnp.exp(-15.0 * t) * jnp.cos(60.0 * t))
        return jnp.full(self.n, q), jnp.zeros(self.n)


def _trajectory(scene, duration: float, n_saves: int):
    motion = _Motion(scene.n_dofs)
    ts = np.linspace(0.0, duration, n_saves)
    q = np.stack([np.asarray(motion.evaluate(t)[0]) for t in ts])
    return pj.Trajectory(
        ts=jnp.asarray(ts),
        q=jnp.asarray(q),
        qdot=jnp.zeros_like(q),
        result=pj.RESULTS.successful,
        num_steps=jnp.asarray(100),
        num_accepted_steps=jnp.asarray(90),
        solution=motion,
    )


def test_tip_plot_follows_the_dense_output_and_labels_every_line(single):
    scene, _ = single
    trajectory = _trajectory(scene, 0.2, 5)  # --duration 0.2 at the default --fps 20
    fig = animation.plot_tip_trajectory(scene, trajectory, equilibrium=np.full(scene.n_dofs, 0.3))
    assert assert_legends_match(fig) == 2
    for ax in fig.axes:
        lines = ax.get_lines()
        assert all(not a.get_label().startswith("_") for a in lines)
        (curve,) = [a for a in lines if a.get_label() == "simulated tip"]
        assert len(curve.get_xdata()) >= 100
        assert curve.get_xdata()[-1] == pytest.approx(0.2)


class _Frames(matplotlib.animation.AbstractMovieWriter):
    """A movie writer that keeps where each frame's panels were drawn (figure fractions)."""

    def setup(self, fig, outfile, dpi=None):
        super().setup(fig, outfile, dpi)
        self.frames = []

    def grab_frame(self, **savefig_kwargs):
        self.fig.savefig(io.BytesIO(), format="rgba", dpi=self.dpi)
        self.frames.append([ax.get_position().bounds for ax in self.fig.axes])

    def finish(self):
        pass


def test_animation_frames_are_laid_out_as_each_frame_alone(single):
    """The animation lays out its first frame and holds that layout: each frame's panels sit
    where that frame laid out on its own puts them."""
    scene, _ = single
    trajectory = _trajectory(scene, 0.2, 3)
    writer = _Frames(fps=20)
    fig, draw, n_frames = animation.animation_frames(scene, trajectory, title="x")
    animation.write_frames(fig, draw, n_frames, writer, "unused.gif", dpi=80)
    assert len(writer.frames) == n_frames and fig.get_layout_engine() is None
    for k in range(n_frames):
        alone, draw_alone, _ = animation.animation_frames(scene, trajectory, title="x")
        draw_alone(k)
        alone.savefig(io.BytesIO(), format="rgba", dpi=80)
        expected = [ax.get_position().bounds for ax in alone.axes]
        np.testing.assert_allclose(writer.frames[k], expected, rtol=0, atol=1e-12)


def test_animation_panels_keep_apart(single):
    scene, _ = single
    fig, draw, n_frames = animation.animation_frames(scene, _trajectory(scene, 0.2, 3), title="x")
    assert n_frames == 3
    draw(n_frames - 1)
    fig.savefig(io.BytesIO(), dpi=80)  # the GIF's resolution, which the layout depends on
    renderer = fig.canvas.get_renderer()
    left, right = fig.axes
    z_label = left.zaxis.label.get_window_extent(renderer)
    gap = right.get_tightbbox(renderer).x0 - z_label.x1
    assert gap > 0.2 * 80, f"the 3D panel's z label is {gap:.1f} px from the next panel"
    assert [ax.get_title() for ax in fig.axes] == ["3D view", "front (x-z)"]
