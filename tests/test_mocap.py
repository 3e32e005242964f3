"""Motion-capture data: MocapDataset, the pacjax CSV, the Motive importer, static frames.

No equilibrium is solved here (fast); synthetic data and fits are in test_identify.py.
"""

import json
import pathlib
import re

import numpy as np
import pytest

import pacjax as pj
from pacjax.io.mocapfile import load_mocap, matrix_to_quaternion, quaternion_to_matrix, save_mocap
from pacjax.io.motive import motive_dataset, read_motive_csv

DATA = pathlib.Path(__file__).resolve().parent / "data"
SITES = [(0, 0.5), (0, 1.0), (1, 1.0, (0.0, 0.01, 0.0))]


def _dataset(n=5, seed=0, **kwargs):
    rng = np.random.default_rng(seed)
    markers = rng.normal(scale=0.1, size=(n, 3, 3))
    markers[1, 2] = np.nan
    return pj.MocapDataset.from_arrays(rng.uniform(0, 0.01, (n, 2)), markers, SITES, **kwargs)


def test_from_arrays_masks_missing_markers_and_slices():
    d = _dataset(6, payload_mass=np.linspace(0, 0.5, 6), time=np.arange(6.0))
    assert d.n_frames == 6 and d.n_markers == 3 and d.n_controls == 2
    assert d.observed.sum() == 6 * 3 - 1 and not d.observed[1, 2]  # masked, frame kept
    part = d[1:4]
    assert part.n_frames == 3 and np.array_equal(part.controls, d.controls[1:4])
    assert np.array_equal(part.payload_mass, d.payload_mass[1:4])
    assert not part.observed[0, 2]
    assert d[np.array([0, 5])].n_frames == 2 and d[2].n_frames == 1
    assert part.sites == d.sites and d.sites[2] == (1, 1.0, (0.0, 0.01, 0.0))
    train, test = d.split(1 / 3, seed=1)
    assert train.n_frames == 4 and test.n_frames == 2
    assert set(train.time) | set(test.time) == set(d.time)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(markers=np.zeros((4, 3))), "markers must have shape"),
        (dict(markers=np.full((4, 3, 3), np.nan)), "every marker position is NaN"),
        (dict(markers=np.full((4, 3, 3), 150.0)), "millimetres"),
        (dict(controls=np.zeros((3, 2))), "controls must have shape"),
        (dict(controls=np.full((4, 2), np.nan)), "controls contains NaN"),
        (dict(sites=[(0, 0.5)]), "sites must list one"),
        (dict(sites=[(0, 0.5), (0, 1.5), (1, 1.0)]), "s must lie in [0, 1]"),
        (dict(sites=[(0, 0.5), (-1, 1.0), (1, 1.0)]), "segment must be an integer"),
        (dict(payload_mass=np.full(4, -1.0)), "payload_mass must be >= 0"),
        (dict(payload_mass=np.full(4, 200.0)), "kg (not g)"),
        (dict(force=np.zeros((4, 2))), "force must have shape"),
    ],
)
def test_bad_arrays_name_the_problem(change, message):
    args = dict(controls=np.zeros((4, 2)), markers=np.full((4, 3, 3), 0.1), sites=SITES)
    args.update(change)
    with pytest.raises(ValueError, match=re.escape(message)):
        pj.MocapDataset.from_arrays(**args)


def test_marker_never_seen_and_partly_nan_are_errors():
    m = np.full((3, 3, 3), 0.1)
    m[:, 1] = np.nan
    with pytest.raises(ValueError, match=r"marker\(s\) \[1\]"):
        pj.MocapDataset.from_arrays(np.zeros((3, 2)), m, SITES)
    m = np.full((3, 3, 3), 0.1)
    m[0, 0, 1] = np.nan
    with pytest.raises(ValueError, match="partly NaN"):
        pj.MocapDataset.from_arrays(np.zeros((3, 2)), m, SITES)


def test_csv_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    rots = quaternion_to_matrix(rng.normal(size=(5, 3, 4)))
    rots[2, 1] = np.nan
    d = _dataset(
        5,
        payload_mass=[0.0, 0.1, 0.2, 0.1, 0.0],
        payload_site=(1, 0.5),
        force=rng.normal(size=(5, 3)),
        force_site=(0, 1.0),
        force_follower=True,
        orientations=rots,
        time=np.arange(5) * 0.5,
    )
    path = tmp_path / "frames.csv"
    save_mocap(path, d)
    text = path.read_text()
    assert text.startswith("# pacjax mocap 1") and "m2_qw" in text
    back = load_mocap(path)
    np.testing.assert_array_equal(back.controls, d.controls)
    np.testing.assert_array_equal(back.markers, d.markers)  # NaN in the same places
    np.testing.assert_array_equal(back.payload_mass, d.payload_mass)
    np.testing.assert_array_equal(back.force, d.force)
    np.testing.assert_allclose(back.orientations, d.orientations, atol=1e-12)
    assert back.sites == d.sites and back.payload_site == (1, 0.5)
    assert back.force_site == (0, 1.0) and back.force_follower
    np.testing.assert_array_equal(back.time, d.time)


def _csv(tmp_path, body, header="# sites = [[0, 1.0]]\n"):
    path = tmp_path / "bad.csv"
    path.write_text("# pacjax mocap 1\n" + header + body)
    return path


@pytest.mark.parametrize(
    "header, body, message",
    [
        ("# sites = [[0, 1.0]]\n", "u0,m0_x,m0_y,m0_z,extra\n0,0,0,0.1,1\n", "unknown column"),
        ("# sites = [[0, 1.0]]\n", "u0,m0_x,m0_y\n0,0,0\n", "missing marker column"),
        ("# sites = [[0, 1.0]]\n", "u0,m0_x,m0_y,m0_z,base_qw\n0,0,0,0.1,1\n", "all of base_qw"),
        (
            "# sites = [[0, 1.0]]\n",
            "u0,m0_x,m0_y,m0_z,base_qw,base_qx,base_qy,base_qz\n0,0,0,0.1,1,1,0,0\n",
            "not a unit quaternion",
        ),
        ("", "u0,m0_x,m0_y,m0_z\n0,0,0,0.1\n", "must give the marker sites"),
        ("# sites = [[0, 1.0]]\n", "u0,m0_x,m0_y,m0_z\n0,0,0,135.4\n", "millimetres"),
        ("# sites = [[0, 1.0]]\n", "u0,m0_x,m0_y,m0_z\n0,,,\n", "every marker position is NaN"),
        ("# sites = [[0, 1.0]]\n", "u0,m0_x,m0_y,m0_z\n0,a,0,0\n", "column m0_x, row 0"),
        ("# sites = [[0, 1.0]]\n# units = 3\n", "u0,m0_x,m0_y,m0_z\n0,0,0,0\n", "unknown header"),
    ],
)
def test_bad_csv_names_the_problem(tmp_path, header, body, message):
    with pytest.raises(ValueError, match=message):
        load_mocap(_csv(tmp_path, body, header))


def test_csv_in_millimetres_is_converted(tmp_path):
    path = _csv(
        tmp_path, "u0,m0_x,m0_y,m0_z\n0,1,2,135.4\n", '# sites = [[0, 1.0]]\n# length_unit = "mm"\n'
    )
    np.testing.assert_allclose(load_mocap(path).markers[0, 0], [0.001, 0.002, 0.1354])


def test_quaternions_round_trip():
    rng = np.random.default_rng(0)
    q = rng.normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q *= np.sign(q[:, :1])
    r = quaternion_to_matrix(q)
    np.testing.assert_allclose(
        np.einsum("kji,kjl->kil", r, r), np.broadcast_to(np.eye(3), r.shape), atol=1e-12
    )
    np.testing.assert_allclose(matrix_to_quaternion(r), q, atol=1e-12)


def test_motive_reader_units_names_and_rotations():
    take = read_motive_csv(DATA / "motive_small.csv")
    assert take.metadata["Length Units"] == "Millimeters"
    assert set(take.markers) == {"Robot:M1", "Robot:M2"} and set(take.rigid_bodies) == {"Tip"}
    assert len(take.time) == 88 and take.time[1] == pytest.approx(0.05)
    np.testing.assert_allclose(take.markers["Robot:M1"][0], [0.0, 1.0, 0.0], atol=1e-6)  # metres
    assert np.isnan(take.markers["Robot:M2"][5]).all()  # occluded: empty cells
    pos, rot = take.rigid_bodies["Tip"]
    np.testing.assert_allclose(pos[0], [0.0, 0.85, 0.0], atol=1e-6)
    # second pose: 30 degrees about z (quaternion x, y, z, w = 0, 0, 0.2588, 0.9659)
    angle = np.degrees(np.arccos((np.trace(rot[40]) - 1) / 2))
    assert angle == pytest.approx(30.0, abs=1e-3)
    np.testing.assert_allclose(rot[40] @ [0, 0, 1], [0, 0, 1], atol=1e-6)


def test_motive_static_frames_with_step_commands():
    take = read_motive_csv(DATA / "motive_small.csv")
    # the robot's log: three commands, each sent as the previous pose's hold ends
    control_time = np.array([-1.0, 1.25, 2.85])
    controls = np.array([[0.0, 0.0], [0.01, 0.0], [0.0, 0.01]])
    d = motive_dataset(
        take,
        ["Robot:M1", "Robot:M2", "Tip"],
        [(0, 0.5), (0, 1.0), (1, 1.0)],
        controls,
        control_time=control_time,
        payload_mass=0.2,
        orientation_names=[None, None, "Tip"],
        window=0.5,
        tolerance=5e-4,
    )
    assert d.n_frames == 3  # one per held pose
    np.testing.assert_array_equal(d.controls, controls)
    np.testing.assert_allclose(
        d.markers[:, 1], [[0, 0.9, 0], [0.03, 0.895, 0], [0, 0.894, 0.035]], atol=1e-4
    )
    np.testing.assert_allclose(d.payload_mass, 0.2)
    assert np.isnan(d.orientations[:, 0]).all() and np.isfinite(d.orientations[:, 2]).all()


def test_motive_errors(tmp_path):
    bad = tmp_path / "x.csv"
    bad.write_text("frame,time\n0,0\n")
    with pytest.raises(ValueError, match="not a Motive CSV"):
        read_motive_csv(bad)
    text = (DATA / "motive_small.csv").read_text().replace("Length Units,Millimeters,", "")
    bad.write_text(text)
    with pytest.raises(ValueError, match="Length Units"):
        read_motive_csv(bad)
    assert read_motive_csv(bad, length_unit="millimeters").markers["Robot:M1"][
        0, 1
    ] == pytest.approx(1.0)
    take = read_motive_csv(DATA / "motive_small.csv")
    with pytest.raises(ValueError, match="no marker or rigid body named 'M9'"):
        take.positions(["M9"])


def test_static_frames_settle_criterion():
    t = np.arange(0.0, 4.0, 0.01)
    x = np.where(t < 1.0, 0.0, np.where(t < 2.0, 0.02 * (t - 1.0), 0.02))  # hold, move, hold
    markers = np.stack([x, np.zeros_like(t), np.zeros_like(t)], -1)[:, None, :]
    runs = pj.static_frames(t, markers, window=0.3, tolerance=1e-4)
    assert len(runs) == 2
    assert t[runs[0][-1]] < 1.0 + 1e-9 and t[runs[1][0]] >= 3.7 - 1e-9  # last 0.3 s of a plateau
    # a command change splits a plateau even when nothing moves
    inputs = (t > 3.0).astype(float)[:, None]
    assert len(pj.static_frames(t, markers, inputs, window=0.3, tolerance=1e-4)) == 3
    with pytest.raises(ValueError, match="increasing"):
        pj.static_frames(t[::-1], markers, window=0.3)
    with pytest.raises(ValueError, match="no static frame"):
        pj.MocapDataset.from_time_series(
            t, np.zeros((len(t), 1)), markers + 0.01 * np.sin(50 * t)[:, None, None], [(0, 1.0)]
        )


def test_frames_that_did_not_converge_are_not_in_the_errors():
    """A failed equilibrium has no prediction: the frame is listed as not converged, its errors
    are NaN and the RMSE is that of the other frames."""
    from pacjax._identify.report import FitErrors

    measured = np.zeros((3, 2, 3))
    predicted = measured.copy()
    predicted[0, :, 0] = 1e-3  # 1 mm off
    predicted[1, :, 0] = 0.2  # the start configuration of a failed solve
    predicted[2, :, 0] = -1e-3
    errors = FitErrors.compute(
        predicted, measured, 1, np.array([True, False, True]), np.zeros((3, 4))
    )
    assert errors.rmse_mm == pytest.approx(1.0)
    assert errors.max_mm == pytest.approx(1.0)
    assert np.isnan(errors.frame_rmse_mm[1]) and np.isnan(errors.tip_error_mm[1])
    summary = errors.summary()
    assert summary["frames_not_converged"] == [1]
    assert summary["frame_rmse_mm"][1] is None
    json.dumps(summary, allow_nan=False)
    none = FitErrors.compute(predicted, measured, 1, np.zeros(3, bool), np.zeros((3, 4)))
    assert none.summary()["rmse_mm"] is None


def test_robot_without_tendons_and_a_turned_base_round_trip(tmp_path):
    angles = np.radians([0.0, 40.0, -75.0])
    turns = np.stack(
        [
            [[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]]
            for a in angles
        ]
    )
    d = pj.MocapDataset.from_arrays(
        np.zeros((3, 0)), np.full((3, 1, 3), 0.1), ((0, 1.0),), base_rotation=turns
    )
    save_mocap(tmp_path / "cable.csv", d)
    header = (tmp_path / "cable.csv").read_text().splitlines()[2]
    assert not any(c.startswith("u") for c in header.split(",")) and "base_qw" in header
    back = load_mocap(tmp_path / "cable.csv")
    assert back.n_controls == 0
    np.testing.assert_allclose(back.base_rotation, turns, atol=1e-12)


def test_motive_names_from_their_old_module_warn_and_work():
    import pacjax.io.motive as motive
    from pacjax.io import mocapfile

    for name in ("read_motive_csv", "motive_dataset", "MotiveTake"):
        with pytest.warns(DeprecationWarning, match=f"mocapfile.{name} is deprecated"):
            assert getattr(mocapfile, name) is getattr(motive, name)
    with pytest.raises(AttributeError, match="no_such_name"):
        mocapfile.no_such_name  # noqa: B018
