"""Identification of material values and rest curvature (issue 26's bodies, fitted): a tapered
two-segment tendon robot made from known E, rho and rest curvature, 1 mm noise, started 2x off."""

import json

import equinox as eqx
import numpy as np
import pytest

import pacjax as pj

E, RHO = 3.0e5, 1300.0
REST = ([0.4, -0.3, 0.1, 0.2], [0.2, 0.0, -0.3, 0.1])  # kx_0, kx_1, ky_0, ky_1 per segment


def make_scene(e=E, rho=RHO, rest=REST):
    pieces = [(0.16, 0.012, 0.009), (0.12, 0.009, 0.006)]
    segments = [
        pj.Segment.from_material(
            length, young_modulus=e, density=rho, radius=r0, radius_tip=r1, rest_curvature=c
        )
        for (length, r0, r1), c in zip(pieces, rest, strict=True)
    ]
    tendons = [
        pj.Tendon(1, a, 0.006, offset_end=0.003, routing="channel", mode="tension")
        for a in (0.0, 2.1, 4.2)
    ]
    return pj.Scene(
        pj.Robot(segments, base_rotation=pj.presets.MOUNTS["hanging"]),
        pj.PolynomialCurvature(1),
        tendons=tendons,
        loads=[pj.Gravity()],
        markers=[(0, 0.33), (0, 0.67), (0, 1.0), (1, 0.33), (1, 0.67), (1, 1.0)],
    )


@pytest.mark.slow  # a fit compiles batched solves and their Jacobians
def test_young_modulus_density_and_rest_curvature_recovered_from_2x_off():
    rng = np.random.default_rng(4)
    n = 48
    tensions = rng.uniform(0.0, 3.0, (n, 3))
    payload = rng.choice([0.0, 0.05, 0.1], n)
    data, _ = pj.synthetic_mocap(
        make_scene(),
        tensions,
        payload_mass=payload,
        exact=True,
        noise=1e-3,
        transform=None,
        seed=5,
    )
    start = make_scene(2 * E, RHO / 2, rest=([0.0] * 4, [0.0] * 4))
    fitted, report = pj.identify(
        start, data, ("young_modulus", "density", "rest_curvature"), progress=False
    )
    assert report.successful, report.message
    for name, truth in (("young_modulus", E), ("density", RHO)):
        p = report.parameters[name]
        value, std = p["value"][0], p["std"][0]
        assert abs(value / truth - 1) < 0.03, (name, value, truth)
        assert abs(value - truth) < 3 * std, (name, value, std)
    rest = report.parameters["rest_curvature"]
    truth = np.concatenate(REST)
    errors = np.abs(np.asarray(rest["value"]) - truth)
    # The short distal segment's curvature moves the markers little: its coefficients are
    # known to 0.05-0.11 rad (one std), the base segment's constant term to 0.012 rad.
    assert np.all(errors < 3 * np.asarray(rest["std"])), (rest["value"], rest["std"])
    seg = fitted.robot.segments[0]
    np.testing.assert_allclose(
        seg.bending_stiffness, report.parameters["young_modulus"]["value"][0] * np.pi * 0.012**4 / 4
    )


@pytest.mark.parametrize(
    ("params", "message"),
    [
        (("young_modulus", "bending_stiffness"), "fit it or bending_stiffness, not both"),
        (("density", "linear_density"), "fit it or linear_density, not both"),
    ],
)
def test_material_parameters_conflict_with_the_fields_they_set(params, message):
    scene = make_scene()
    data = pj.MocapDataset.from_arrays(
        np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0]]),
        np.random.default_rng(0).normal(size=(2, 6, 3)),
        scene.markers,
    )
    with pytest.raises(ValueError, match=message):
        pj.identify(scene, data, params, progress=False)


def test_young_modulus_needs_a_section():
    seg = pj.Segment(0.1, 0.01, 100.0)  # stiffness entered directly, no radius
    scene = pj.Scene(pj.Robot([seg]), pj.PCC(), loads=[pj.Gravity()], markers=[(0, 1.0)])
    data = pj.MocapDataset.from_arrays(
        np.zeros((2, 0)),
        [[[0.0, 0.0, 0.1]], [[0.0, 0.01, 0.1]]],
        scene.markers,
        payload_mass=[0.0, 0.01],
    )
    with pytest.raises(ValueError, match="segment 0 has no section"):
        pj.identify(scene, data, ("young_modulus",), progress=False)


@pytest.fixture(scope="module")
def scaled_robot():
    """An inextensible polynomial robot with length-mode tendons and no payload: scaling EI,
    the tendon gain and the density together leaves every pose unchanged, and GJ has no effect
    (no twist strain)."""
    seg = pj.Segment(0.2, 0.01, 1e3, linear_density=0.2, radius=0.01, extensible=False)
    tendons = [
        pj.Tendon(0, a, 0.008, gain=2e3, guides=(0.0, 0.25, 0.5, 0.75, 1.0))
        for a in (0.0, 2.1, 4.2)
    ]
    scene = pj.Scene(
        pj.Robot([seg], base_rotation=pj.presets.MOUNTS["horizontal"]),
        pj.PolynomialCurvature(1),
        tendons=tendons,
        loads=[pj.Gravity()],
        markers=[(0, 0.5), (0, 1.0)],
    )
    u = np.random.default_rng(2).uniform(0.0, 0.004, (8, 3))
    data, _ = pj.synthetic_mocap(scene, u, exact=True, noise=1e-3, transform=None, seed=1)
    return scene, data


@pytest.mark.slow
def test_a_parameter_without_effect_is_not_identified_never_std_0(scaled_robot):
    scene, data = scaled_robot
    _, report = pj.identify(scene, data, ("bending_stiffness", "torsion_stiffness"), progress=False)
    torsion = report.parameters["torsion_stiffness"]
    assert torsion["std"] == [None] and torsion["relative_std"] == [None]
    assert report.identifiable == [True, False]
    assert report.parameters["bending_stiffness"]["std"][0] > 0
    assert "Not identified by these data" in report.to_markdown()


@pytest.mark.slow
def test_parameters_that_only_act_together_are_not_identified(scaled_robot):
    scene, data = scaled_robot
    _, report = pj.identify(
        scene, data, ("bending_stiffness", "tendon_gain", "linear_density"), progress=False
    )
    assert report.identifiable == [False, False, False]
    for name in ("bending_stiffness", "tendon_gain", "linear_density"):
        assert report.parameters[name]["std"] == [None]


@pytest.mark.slow
def test_no_fitted_value_leaves_its_bounds(scaled_robot):
    scene, data = scaled_robot
    ei = float(scene.robot.segments[0].bending_stiffness)

    def with_ei(value):
        return eqx.tree_at(lambda s: s.robot.segments[0].bending_stiffness, scene, value)

    # The optimum (the truth) lies below the lower bound: the fit ends on it and says so.
    fitted, report = pj.identify(
        with_ei(3 * ei),
        data,
        ("bending_stiffness",),
        bounds={"bending_stiffness": (1.5 * ei, None)},
        progress=False,
    )
    assert float(fitted.robot.segments[0].bending_stiffness) == pytest.approx(1.5 * ei, rel=1e-12)
    assert report.parameters["bending_stiffness"]["at_bound"] == ["lower"]
    assert "At a bound" in report.to_markdown()
    # Random starts and bounds around them: every fitted value inside.
    rng = np.random.default_rng(7)
    for _ in range(3):
        lo, hi = np.sort(rng.uniform(0.3, 3.0, 2)) * ei
        start = rng.uniform(lo, hi)
        fitted, report = pj.identify(
            with_ei(start),
            data,
            ("bending_stiffness", "tendon_gain"),
            bounds={"bending_stiffness": (lo, hi), "tendon_gain": (1e3, 4e3)},
            progress=False,
        )
        value = float(fitted.robot.segments[0].bending_stiffness)
        assert lo <= value <= hi
        assert all(1e3 <= float(t.gain) <= 4e3 for t in fitted.tendons)
    with pytest.raises(ValueError, match="outside its bounds"):
        pj.identify(
            with_ei(ei),
            data,
            ("bending_stiffness",),
            bounds={"bending_stiffness": (2 * ei, 3 * ei)},
            progress=False,
        )


def _about_y(angle):
    c, s = np.cos(angle), np.sin(angle)
    # The hanging mount (rest axis along world -z) turned about world y by ``angle``.
    turn = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return turn @ pj.presets.MOUNTS["hanging"]


def _turning_cable(ei, markers, angles_deg, noise, rest=None, loads=(), seed=0):
    """An inextensible cable (0.4 m, PolynomialCurvature(1), gravity and ``loads``) and its
    synthetic frames with the base turned about world y to each of ``angles_deg``."""
    seg = pj.Segment(0.4, ei, 1e3, linear_density=0.08, rest_curvature=rest, extensible=False)
    scene = pj.Scene(
        pj.Robot([seg]), pj.PolynomialCurvature(1), loads=[pj.Gravity(), *loads], markers=markers
    )
    angles = np.radians(np.asarray(angles_deg, float))
    data, _ = pj.synthetic_mocap(
        scene,
        np.zeros((angles.size, 0)),
        base_rotation=np.stack([_about_y(a) for a in angles]),
        exact=True,
        noise=noise,
        transform=None,
        seed=seed,
    )
    return scene, data, angles


@pytest.mark.slow
def test_cable_on_a_turning_base_fitted_on_small_angles_predicts_the_others():
    """A pre-curved cable (one segment, distributed and end mass) clamped at a base turned
    through +-165 degrees: EI and rest curvature from the poses within 60 degrees of hanging,
    the others predicted."""
    ei, rest = 2.5e-3, [1.2, -0.4, 0.0, 0.0]
    scene, data, angles = _turning_cable(
        ei,
        [(0, 0.2), (0, 0.4), (0, 0.6), (0, 0.8), (0, 1.0)],
        np.arange(-165.0, 166.0, 7.5),
        noise=1e-3,
        rest=rest,
        loads=[pj.PointMass(0.01, 0)],
        seed=11,
    )
    near = np.flatnonzero(np.abs(angles) <= np.radians(60.0) + 1e-9)
    far = np.flatnonzero(np.abs(angles) > np.radians(60.0) + 1e-9)
    start = eqx.tree_at(
        lambda s: (s.robot.segments[0].bending_stiffness, s.robot.segments[0].rest_curvature),
        scene,
        (2 * ei, np.zeros(4)),
    )
    fitted, report = pj.identify(
        start,
        data[near],
        ("bending_stiffness", "rest_curvature"),
        validation=data[far],
        progress=False,
    )
    assert report.successful, report.message
    got = float(fitted.robot.segments[0].bending_stiffness)
    assert abs(got / ei - 1) < 0.03, got
    value = np.asarray(report.parameters["rest_curvature"]["value"])
    std = np.asarray(report.parameters["rest_curvature"]["std"])
    # The rest bending angle kx_0 + kx_1 / 2 within 3 % (measured 0.4 %), each coefficient
    # within 3 std (the linear one is known to 0.025 rad: 6 % of its value at 1 mm noise).
    angle = value[0] + value[1] / 2
    assert abs(angle / (rest[0] + rest[1] / 2) - 1) < 0.03, (value, std)
    assert np.all(np.abs(value - rest) < 3 * std), (value, std)
    # 1 mm per coordinate: a marker's distance error has an RMS of sqrt(3) mm.
    assert report.validation.rmse_mm < 1.5 * np.sqrt(3), report.validation.rmse_mm


@pytest.mark.slow
def test_a_gaussian_prior_pulls_the_fit_and_narrows_its_std(scaled_robot):
    scene, data = scaled_robot
    ei = float(scene.robot.segments[0].bending_stiffness)
    _, free = pj.identify(scene, data, ("bending_stiffness",), progress=False)
    _, tight = pj.identify(
        scene,
        data,
        ("bending_stiffness",),
        priors={"bending_stiffness": (1.2 * ei, 1e-4 * ei)},
        progress=False,
    )
    _, loose = pj.identify(
        scene,
        data,
        ("bending_stiffness",),
        priors={"bending_stiffness": (1.2 * ei, 10 * ei)},
        progress=False,
    )
    value = {
        k: r.parameters["bending_stiffness"]["value"][0]
        for k, r in (("free", free), ("tight", tight), ("loose", loose))
    }
    std = {
        k: r.parameters["bending_stiffness"]["std"][0]
        for k, r in (("free", free), ("tight", tight), ("loose", loose))
    }
    assert value["tight"] == pytest.approx(1.2 * ei, rel=1e-3)  # the prior dominates
    assert value["loose"] == pytest.approx(value["free"], rel=1e-3)  # the data dominate
    assert std["tight"] < 0.05 * std["free"]
    with pytest.raises(ValueError, match="std > 0"):
        pj.identify(
            scene,
            data,
            ("bending_stiffness",),
            priors={"bending_stiffness": (ei, 0.0)},
            progress=False,
        )


@pytest.mark.slow
def test_cli_fits_a_robot_without_tendons_on_a_turning_base(tmp_path):
    from click.testing import CliRunner

    from pacjax.cli.main import cli
    from pacjax.io.mocapfile import save_mocap
    from pacjax.io.scenefile import save_scene

    ei = 2.5e-3
    scene, data, _ = _turning_cable(
        ei, [(0, 0.5), (0, 1.0)], np.arange(-60.0, 61.0, 15.0), noise=0.0
    )
    save_mocap(tmp_path / "cable.csv", data)
    start = eqx.tree_at(lambda s: s.robot.segments[0].bending_stiffness, scene, 2 * ei)
    save_scene(tmp_path / "cable.toml", start, name="cable")
    result = CliRunner().invoke(
        cli,
        [
            "fit",
            str(tmp_path / "cable.toml"),
            str(tmp_path / "cable.csv"),
            "--params",
            "bending_stiffness",
            "--holdout",
            "0",
            "--no-plot",
            "--out",
            str(tmp_path / "out"),
        ],
        catch_exceptions=False,
    )
    assert result.exit_code == 0, result.output
    report = json.loads((tmp_path / "out" / "cable_fit.json").read_text())
    assert report["parameters"]["bending_stiffness"]["value"][0] == pytest.approx(ei, rel=1e-6)
