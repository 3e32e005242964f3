"""Per-frame scene changes in identification (issue 27, item 5): gravity directions, a user's
per-frame hook, and the CSV's ``gravity_*`` and ``holdout`` columns."""

import equinox as eqx
import numpy as np
import pytest

import pacjax as pj
from pacjax.io.mocapfile import load_mocap, save_mocap

EI = 2.5e-3


def cable(ei=EI):
    """A cable (0.4 m, clamped pointing down) with a clip of per-frame mass at its middle."""
    seg = pj.Segment(0.4, ei, 1e3, linear_density=0.08, extensible=False)
    return pj.Scene(
        pj.Robot([seg], base_rotation=pj.presets.MOUNTS["hanging"]),
        pj.PolynomialCurvature(1),
        loads=[pj.Gravity(), pj.PointMass(0.0, 0, 0.5)],
        markers=[(0, 0.25), (0, 0.5), (0, 0.75), (0, 1.0)],
    )


def clip_mass(scene, values):
    """The per-frame hook: the clip's mass (kg) of each frame."""
    return eqx.tree_at(lambda s: s.loads[1].mass, scene, values["clip_mass"])


def tilted(angles_deg):
    """Gravity tilted about world y by each angle (from straight down)."""
    a = np.radians(np.asarray(angles_deg, float))
    return np.stack([np.sin(a), np.zeros_like(a), -np.cos(a)], 1)


@pytest.mark.slow  # a fit compiles batched solves and their Jacobians
def test_gravity_directions_and_a_hook_per_frame_recover_ei():
    angles = np.linspace(-60.0, 60.0, 9)
    clips = np.linspace(0.0, 0.02, 9)[::-1]
    data, _ = pj.synthetic_mocap(
        cable(),
        np.zeros((9, 0)),
        gravity_direction=tilted(angles),
        frame_values={"clip_mass": clips},
        frame_update=clip_mass,
        exact=True,
        noise=1e-3,
        transform=None,
        seed=3,
    )
    fitted, report = pj.identify(
        cable(2 * EI), data, holdout=[2, 6], frame_update=clip_mass, progress=False
    )
    assert report.successful, report.message
    value = float(fitted.robot.segments[0].bending_stiffness)
    assert abs(value / EI - 1) < 0.03
    assert abs(value - EI) < 3 * report.parameters["bending_stiffness"]["std"][0]
    # The held-out frames, under their own gravity and clip, are predicted to the noise.
    assert report.validation.rmse_mm < 1.5 * np.sqrt(3)
    # The same frames with gravity straight down are another experiment: far off.
    _, plain = pj.identify(
        cable(),
        dataclass_replace(data, gravity_direction=None),
        frame_update=clip_mass,
        max_iterations=0,
        progress=False,
    )
    assert plain.train.rmse_mm > 20 * report.train.rmse_mm


def dataclass_replace(data, **changes):
    import dataclasses

    return dataclasses.replace(data, **changes)


def test_frame_values_need_a_hook_and_a_gravity_direction_needs_gravity():
    markers = np.random.default_rng(0).normal(scale=0.1, size=(2, 4, 3))
    sites = cable().markers
    values = pj.MocapDataset.from_arrays(
        np.zeros((2, 0)), markers, sites, frame_values={"clip_mass": [0.0, 0.01]}
    )
    with pytest.raises(ValueError, match=r"frame_values \['clip_mass'\] but no frame_update"):
        pj.identify(cable(), values, progress=False)
    with pytest.raises(ValueError, match="frame_update is given but the dataset has no"):
        plain = pj.MocapDataset.from_arrays(np.zeros((2, 0)), markers, sites, payload_mass=[0, 1])
        pj.identify(cable(), plain, frame_update=clip_mass, progress=False)
    no_gravity = pj.Scene(cable().robot, pj.PolynomialCurvature(1), markers=sites)
    turned = pj.MocapDataset.from_arrays(
        np.zeros((2, 0)), markers, sites, gravity_direction=tilted([0.0, 30.0])
    )
    with pytest.raises(ValueError, match="gravity_direction but the scene has no Gravity"):
        pj.identify(no_gravity, turned, progress=False)
    with pytest.raises(ValueError, match=r"gravity_direction\[1\] is not a unit vector"):
        pj.MocapDataset.from_arrays(
            np.zeros((2, 0)), markers, sites, gravity_direction=[[0, 0, -1], [0, 0, -2]]
        )
    with pytest.raises(ValueError, match="holdout must be 0 or 1"):
        pj.MocapDataset.from_arrays(np.zeros((2, 0)), markers, sites, holdout=[0, 2])


def test_csv_round_trip_of_gravity_directions_and_holdout_column(tmp_path):
    markers = np.random.default_rng(1).normal(scale=0.1, size=(3, 4, 3))
    data = pj.MocapDataset.from_arrays(
        np.zeros((3, 0)),
        markers,
        cable().markers,
        gravity_direction=tilted([-20.0, 0.0, 35.0]),
        holdout=[0, 1, 0],
    )
    save_mocap(tmp_path / "frames.csv", data)
    back = load_mocap(tmp_path / "frames.csv")
    np.testing.assert_allclose(back.gravity_direction, data.gravity_direction, atol=1e-12)
    assert back.holdout.tolist() == [False, True, False]
    np.testing.assert_allclose(back.markers, markers)
    text = (tmp_path / "frames.csv").read_text().replace("gravity_z", "gravity_w")
    (tmp_path / "bad.csv").write_text(text)
    with pytest.raises(ValueError, match="unknown column"):
        load_mocap(tmp_path / "bad.csv")
