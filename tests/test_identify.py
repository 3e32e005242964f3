"""Identification from motion-capture frames: recovery of known parameters, uncertainty,
reports, the CLI, and bad input.

One small scene structure for the whole module (one PCC segment mounted horizontally, three
length-mode tendons, gravity, a tip payload that changes per frame, two markers), so that the
batch solver and the Jacobian compile once. Data are synthetic from the same structure
(``exact=True``): the fitted model can then match them, and recovery is checked to tight
tolerance; with 1 mm noise the error must lie within the reported uncertainty.
"""

import json
import re

import numpy as np
import optax
import pytest
from click.testing import CliRunner

import pacjax as pj
from pacjax.cli.main import cli
from pacjax.io.mocapfile import save_mocap
from pacjax.io.scenefile import load_scene, save_scene

# The whole file runs in CI's slow step:
# fits compile batched solves and their Jacobians: minutes on 2 cores.
pytestmark = pytest.mark.slow

TRUE_EI = 0.02
N_FRAMES = 16


def make_scene(ei=TRUE_EI, gain=2.0e3, mode="length"):
    seg = pj.Segment(0.15, ei, 600.0, linear_density=0.3, radius=0.012)
    robot = pj.Robot([seg], base_rotation=pj.presets.MOUNTS["horizontal"])
    tendons = [
        pj.Tendon(
            0, a, 0.01, gain=gain if mode == "length" else None, guides=(0.0, 0.5, 1.0), mode=mode
        )
        for a in (0.0, 2.1, 4.2)
    ]
    return pj.Scene(
        robot, pj.PCC(), tendons=tendons, loads=(pj.Gravity(),), markers=[(0, 0.5), (0, 1.0)]
    )


def commands(n, seed):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.0, 0.006, (n, 3)), rng.choice([0.0, 0.05, 0.1], n)


@pytest.fixture(scope="module")
def clean():
    u, mass = commands(N_FRAMES, 1)
    data, truth = pj.synthetic_mocap(
        make_scene(), u, payload_mass=mass, exact=True, noise=0.0, transform=None
    )
    return data, truth


@pytest.fixture(scope="module")
def noisy():
    u, mass = commands(N_FRAMES, 2)
    return pj.synthetic_mocap(
        make_scene(), u, payload_mass=mass, exact=True, noise=1e-3, dropout=0.1, seed=3
    )


def test_synthetic_data_are_the_model_seen_through_the_transform(noisy):
    data, truth = noisy
    assert data.n_frames == N_FRAMES and truth.dropped.size == 0
    assert 0 < (~data.observed).sum() < data.observed.size  # dropouts, masked
    seen = data.observed
    expected = truth.markers @ truth.rotation.T + truth.translation
    err = (data.markers - expected)[seen]
    assert 0.7e-3 < err.std() < 1.3e-3  # the 1 mm noise
    assert np.allclose(truth.rotation.T @ truth.rotation, np.eye(3))


def test_recovers_bending_stiffness_from_3x_off_noise_free(clean):
    data, _ = clean
    fitted, report = pj.identify(
        make_scene(3 * TRUE_EI), data, ("bending_stiffness",), progress=False
    )
    ei = float(fitted.robot.segments[0].bending_stiffness)
    assert abs(ei / TRUE_EI - 1) < 1e-6, (ei, report.message)
    assert report.successful, report.message
    assert report.train.rmse_mm < 2e-3
    assert report.parameters["bending_stiffness"]["value"] == [pytest.approx(ei)]
    assert report.parameters["bending_stiffness"]["initial"] == [pytest.approx(3 * TRUE_EI)]
    losses = np.asarray(report.loss_history)
    assert losses[0] > 1e2 * max(losses[-1], 1e-20) and np.all(np.diff(losses) <= 0)
    assert report.iterations == len(losses) - 1 and report.evaluations >= report.iterations


def test_noisy_fit_with_unknown_transform_within_uncertainty(noisy):
    data, truth = noisy
    fitted, report = pj.identify(
        make_scene(TRUE_EI / 3),
        data,
        ("bending_stiffness", "tendon_gain", "mocap_transform"),
        holdout=0.25,
        progress=False,
    )
    p = report.parameters["bending_stiffness"]
    ei, std = p["value"][0], p["std"][0]
    assert std is not None and 0 < std < 0.05 * TRUE_EI
    assert abs(ei - TRUE_EI) < 4 * std, (ei, std)
    assert abs(ei / TRUE_EI - 1) < 0.05
    gain = report.parameters["tendon_gain"]
    assert abs(gain["value"][0] - 2.0e3) < 4 * gain["std"][0]
    np.testing.assert_allclose(report.rotation, truth.rotation, atol=0.02)
    np.testing.assert_allclose(report.translation, truth.translation, atol=0.005)
    noise_rms = np.sqrt(3) * 1.0  # mm: 1 mm per coordinate
    assert report.validation is not None and len(report.validation.frame_rmse_mm) == 4
    assert report.validation.rmse_mm < 1.5 * noise_rms
    assert report.train.rmse_mm < 1.5 * noise_rms
    assert all(report.identifiable)
    text = report.to_markdown()
    assert "bending_stiffness" in text and "held-out" in text


def test_robust_loss_and_optax_optimiser_reduce_the_loss(clean):
    data, _ = clean
    markers = data.markers.copy()
    markers[3, 1] += 0.05  # one gross outlier (5 cm)
    bad = pj.MocapDataset.from_arrays(data.controls, markers, data.sites, data.payload_mass)
    _, l2 = pj.identify(make_scene(2 * TRUE_EI), bad, progress=False)
    fitted, hub = pj.identify(make_scene(2 * TRUE_EI), bad, loss="huber", progress=False)
    err_l2 = abs(l2.parameters["bending_stiffness"]["value"][0] / TRUE_EI - 1)
    err_hub = abs(hub.parameters["bending_stiffness"]["value"][0] / TRUE_EI - 1)
    assert err_hub < 0.5 * err_l2
    _, adam = pj.identify(
        make_scene(2 * TRUE_EI), data, optimizer=optax.adam(0.1), max_iterations=15, progress=False
    )
    assert adam.loss_history[-1] < 0.1 * adam.loss_history[0]


def test_report_json_and_fitted_scene_file(clean, tmp_path):
    data, _ = clean
    fitted, report = pj.identify(make_scene(2 * TRUE_EI), data, max_iterations=3, progress=False)
    report.to_json(tmp_path / "r.json")
    d = json.loads((tmp_path / "r.json").read_text())
    assert d["iterations"] == report.iterations <= 3
    assert len(d["train"]["frame_rmse_mm"]) == N_FRAMES and len(d["train"]["marker_rmse_mm"]) == 2
    assert d["validation"] is None
    save_scene(tmp_path / "fitted.toml", fitted)
    from pacjax.io.scenefile import load_scene

    back, _, _ = load_scene(tmp_path / "fitted.toml")
    assert float(back.robot.segments[0].bending_stiffness) == pytest.approx(
        report.parameters["bending_stiffness"]["value"][0]
    )


def test_cli_fit_writes_scene_report_and_plots(clean, tmp_path):
    data, _ = clean
    save_scene(
        tmp_path / "arm.toml",
        make_scene(2 * TRUE_EI),
        [0.001, 0.0, 0.002],
        name="arm",
        description="three tendons",
    )
    save_mocap(tmp_path / "frames.csv", data)
    result = CliRunner().invoke(
        cli,
        [
            "fit",
            str(tmp_path / "arm.toml"),
            str(tmp_path / "frames.csv"),
            "--params",
            "bending_stiffness",
            "--holdout-frames",
            "1, 5,9,12",
            "--out",
            str(tmp_path / "out"),
        ],
        catch_exceptions=False,
    )
    assert result.exit_code == 0, result.output
    out = tmp_path / "out"
    for name in (
        "arm_fitted.toml",
        "arm_fit.json",
        "arm_fit.md",
        "arm_fit_loss.png",
        "arm_fit_backbones.png",
        "arm_fit_errors.png",
    ):
        assert (out / name).stat().st_size > 0, name
    report = json.loads((out / "arm_fit.json").read_text())
    assert report["parameters"]["bending_stiffness"]["value"][0] == pytest.approx(TRUE_EI, rel=1e-5)
    assert report["validation"]["frames"] == 4
    assert "held-out RMSE" in result.output
    # The fitted scene keeps the input's controls and says what it was fitted to.
    fitted, controls, extra = load_scene(out / "arm_fitted.toml")
    np.testing.assert_array_equal(controls, [0.001, 0.0, 0.002])
    assert extra["name"] == "arm_fitted"
    assert extra["description"] == "fitted to frames.csv; three tendons"
    assert float(fitted.robot.segments[0].bending_stiffness) == pytest.approx(TRUE_EI, rel=1e-5)
    bad = CliRunner().invoke(
        cli,
        [
            "fit",
            str(tmp_path / "arm.toml"),
            str(tmp_path / "frames.csv"),
            "--holdout-frames",
            "3,99",
            "--no-plot",
            "--out",
            str(tmp_path / "o2"),
        ],
    )
    assert bad.exit_code == 1 and "holdout frame 99 does not exist" in bad.output


def test_cli_fit_bad_data_is_one_line(tmp_path):
    save_scene(tmp_path / "arm.toml", make_scene(), name="arm")
    (tmp_path / "bad.csv").write_text("# sites = [[0, 1.0]]\nu0,u1,m0_x,m0_y,m0_z\n0,0,0,0,0.1\n")
    result = CliRunner().invoke(cli, ["fit", str(tmp_path / "arm.toml"), str(tmp_path / "bad.csv")])
    assert result.exit_code == 1
    assert "2 control column(s) but the scene has 3 tendon(s)" in result.output
    assert "Traceback" not in result.output


def _data(n=4, vary=True, markers=None):
    u = np.tile([0.001, 0.0, 0.0], (n, 1))
    if vary:
        u[:, 0] = np.linspace(0.0, 0.004, n)
    m = np.random.default_rng(0).normal(scale=0.05, size=(n, 2, 3)) if markers is None else markers
    return pj.MocapDataset.from_arrays(u, m, [(0, 0.5), (0, 1.0)])


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(params=("stiffness",)), "unknown parameter 'stiffness'"),
        (dict(params=()), "params is empty"),
        (dict(per_segment=("axial_stiffness",)), "not in params"),
        (dict(params=("linear_density", "linear_density")), "twice"),
        (dict(loss="cauchy"), "loss must be"),
        (dict(noise=0.0), "must be > 0"),
        (dict(holdout=0.2, validation="x"), "either validation= or holdout="),
        (dict(optimizer="bfgs"), "optimizer must be"),
        (dict(mocap_transform=(np.ones((3, 3)), np.zeros(3))), "proper rotation"),
    ],
)
def test_bad_arguments(kwargs, message):
    args = dict(params=("bending_stiffness",))
    args.update(kwargs)
    with pytest.raises((ValueError, TypeError), match=re.escape(message)):
        pj.identify(make_scene(), _data(), **args)


def test_bad_data():
    with pytest.raises(ValueError, match="no variation"):
        pj.identify(make_scene(), _data(vary=False))
    frozen = np.tile(np.random.default_rng(1).normal(scale=0.05, size=(1, 2, 3)), (4, 1, 1))
    with pytest.raises(ValueError, match="frozen"):
        pj.identify(make_scene(), _data(markers=frozen))
    u = np.zeros((3, 2))
    two = pj.MocapDataset.from_arrays(u, np.full((3, 2, 3), 0.1), [(0, 0.5), (0, 1.0)])
    with pytest.raises(ValueError, match="2 control column"):
        pj.identify(make_scene(), two)
    far = pj.MocapDataset.from_arrays(np.zeros((2, 3)), np.full((2, 1, 3), 0.1), [(3, 1.0)])
    with pytest.raises(ValueError, match="segment 3 does not exist"):
        pj.identify(make_scene(), far)
    with pytest.raises(ValueError, match="tension-mode tendons have no gain"):
        pj.identify(make_scene(mode="tension"), _data(), ("tendon_gain",))
    with pytest.raises(ValueError, match="linear_density: the starting value must be > 0"):
        seg = pj.Segment(0.15, 0.02, 600.0)
        scene = pj.Scene(pj.Robot([seg]), pj.PCC(), tendons=make_scene().tendons)
        pj.identify(scene, _data(), ("linear_density",))
    loaded = pj.MocapDataset.from_arrays(
        _data().controls, _data().markers, [(0, 0.5), (0, 1.0)], payload_mass=np.ones(4)
    )
    weightless = pj.Scene(
        pj.Robot([pj.Segment(0.15, 0.02, 600.0)]), pj.PCC(), tendons=make_scene().tendons
    )
    with pytest.raises(ValueError, match="no Gravity"):
        pj.identify(weightless, loaded)


def test_high_fidelity_scene_structure():
    scene = make_scene()
    fine = pj.high_fidelity(scene, subdivisions=3, stiffening_rate=2.0)
    assert fine.n_segments == 3 and isinstance(fine.model, pj.PolynomialCurvature)
    assert float(fine.robot.total_length) == pytest.approx(0.15)
    assert all(float(s.axial_stiffness) == pytest.approx(1800.0) for s in fine.robot.segments)
    assert all(float(s.stiffening.rate) == 2.0 for s in fine.robot.segments)
    assert [t.segment for t in fine.tendons] == [2, 2, 2] and fine.tendons[0].s == 1.0
    assert fine.markers[0][:2] == (1, 0.5) and fine.markers[1][:2] == (2, 1.0)
    bowden = pj.presets.stella2023(n_sections=2)
    with pytest.raises(ValueError, match="Bowden"):
        pj.high_fidelity(bowden, subdivisions=2)


@pytest.mark.slow
def test_orientations_and_marker_offsets_are_recovered():
    """Orientation residuals and marker stand-offs (a second compilation: slow)."""
    truth = make_scene()
    sites = [(0, 0.5), (0, 1.0, (0.0, 0.012, 0.004))]
    u, mass = commands(N_FRAMES, 4)
    data, _ = pj.synthetic_mocap(
        truth,
        u,
        sites=sites,
        payload_mass=mass,
        exact=True,
        noise=0.0,
        transform=None,
        orientations=True,
        orientation_noise=0.0,
    )
    fitted, report = pj.identify(
        make_scene(2 * TRUE_EI), data, ("bending_stiffness", "marker_offsets"), progress=False
    )
    assert report.parameters["bending_stiffness"]["value"][0] == pytest.approx(TRUE_EI, rel=1e-5)
    np.testing.assert_allclose(fitted.markers[1][2], sites[1][2], atol=1e-6)
    np.testing.assert_allclose(fitted.markers[0][2], 0.0, atol=1e-6)
    # measured 0.0015 deg at the solver tolerance (1e-10)
    assert np.nanmax(report.train.orientation_error_deg) < 1e-2
