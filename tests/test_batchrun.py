"""``pacjax batch`` and :mod:`pacjax.cli.batchrun`: samplers, default ranges, the HDF5 columns, bad
input rejected before anything is compiled."""

import json

import h5py
import numpy as np
import pytest
from checks import scaled_residual
from click.testing import CliRunner

import pacjax as pj
from pacjax._model.inputs import static_load_sites
from pacjax.cli import batchrun
from pacjax.cli.main import cli
from pacjax.io.scenefile import scene_from_toml

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

# The structure of tests/test_batch.py's scene (one linear-curvature segment, three
# tendons, gravity along x, a point mass), so the persistent compilation cache is shared.
SCENE_TOML = """
name = "one_segment"
markers = [[0, 0.5], [0, 1.0]]

[model]
type = "PolynomialCurvature"
order = 1

[[segments]]
length = 0.15
bending_stiffness = 0.05
axial_stiffness = 2000.0
linear_density = 0.3

[[tendons]]
segment = 0
angle_deg = 0.0
offset = 0.02
gain = 5e3

[[tendons]]
segment = 0
angle_deg = 120.0
offset = 0.02
gain = 5e3

[[tendons]]
segment = 0
angle_deg = 240.0
offset = 0.02
gain = 5e3

[[loads]]
type = "gravity"
direction = [1.0, 0.0, 0.0]

[[loads]]
type = "point_mass"
mass = 0.1
segment = 0
"""


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "one_segment.toml"
    path.write_text(SCENE_TOML)
    return path


@pytest.fixture(scope="module")
def scene():
    return scene_from_toml(SCENE_TOML)[0]


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


# ------------------------------------------------------------------------------ samplers
def test_lhs_is_stratified_in_every_tendon():
    low, high = np.array([0.0, -1.0, 2.0]), np.array([0.01, 1.0, 2.5])
    n = 37
    u = batchrun.sample_commands("lhs", n, low, high, seed=3)
    assert u.shape == (n, 3)
    strata = np.floor((u - low) / (high - low) * n).astype(int)
    for j in range(3):  # one sample in each of the n strata of every tendon's range
        assert sorted(strata[:, j]) == list(range(n))
    again = batchrun.sample_commands("lhs", n, low, high, seed=3)
    np.testing.assert_array_equal(u, again)
    other = batchrun.sample_commands("lhs", n, low, high, seed=4)
    assert not np.array_equal(u, other)


def test_uniform_samples_lie_in_the_ranges():
    low, high = np.array([0.0, 0.5]), np.array([0.02, 0.5])  # a fixed tendon is allowed
    u = batchrun.sample_commands("uniform", 500, low, high, seed=0)
    assert u.shape == (500, 2)
    assert np.all(u >= low) and np.all(u <= high)
    assert np.all(u[:, 1] == 0.5)
    assert u[:, 0].min() < 0.002 and u[:, 0].max() > 0.018


@pytest.mark.parametrize(("n", "m", "k"), [(27, 3, 3), (63, 3, 3), (64, 3, 4), (1000, 9, 2)])
def test_grid_is_the_largest_full_grid_within_n(n, m, k):
    low, high = np.zeros(m), np.arange(1.0, m + 1)
    u = batchrun.sample_commands("grid", n, low, high)
    assert u.shape == (k**m, m)
    assert len({tuple(row) for row in u}) == k**m
    for j in range(m):
        np.testing.assert_allclose(np.unique(u[:, j]), np.linspace(0.0, high[j], k))


def test_default_ranges_from_the_tendons():
    seg = pj.Segment(0.2, 0.04, 1000.0)
    tendons = [
        pj.Tendon(1, 0.0, 0.01, gain=1e3),  # free, base to the end of segment 1: 0.4 m
        pj.Tendon(1, 0.0, 0.01, gain=1e3, bowden=True),  # its own segment: 0.2 m
        pj.Tendon(0, 0.0, 0.01, mode="tension"),
    ]
    scene = pj.Scene(pj.Robot([seg, seg]), pj.PCC(), tendons=tendons)
    low, high = batchrun.default_ranges(scene)
    np.testing.assert_array_equal(low, 0.0)
    f = batchrun.PULL_IN_FRACTION
    expected_tension = 0.04 * batchrun.TENSION_BEND_ANGLE / (0.2 * 0.01)
    np.testing.assert_allclose(high, [f * 0.4, f * 0.2, expected_tension])


def test_bad_sampling_input_is_rejected():
    with pytest.raises(ValueError, match="one per tendon"):
        batchrun.check_ranges([0.0, 0.0], 0.01, 3)
    with pytest.raises(ValueError, match="low must be <= high.*tendon 1"):
        batchrun.check_ranges([0.0, 0.02, 0.0], 0.01, 3)
    with pytest.raises(ValueError, match="high must be finite"):
        batchrun.check_ranges(0.0, [0.01, np.nan, 0.01], 3)
    with pytest.raises(ValueError, match="low must be numbers"):
        batchrun.check_ranges("a", 0.01, 3)
    low, high = np.zeros(3), np.ones(3)
    with pytest.raises(ValueError, match="sampler must be one of"):
        batchrun.sample_commands("sobol", 8, low, high)
    with pytest.raises(ValueError, match="n must be >= 1"):
        batchrun.sample_commands("uniform", 0, low, high)
    with pytest.raises(TypeError, match="n must be an integer"):
        batchrun.sample_commands("uniform", 8.0, low, high)
    with pytest.raises(ValueError, match="grid over 3 tendons needs n >= 2\\*\\*3"):
        batchrun.sample_commands("grid", 7, low, high)
    scene = pj.Scene(pj.Robot([pj.Segment(0.2, 0.04, 1000.0)]), pj.PCC())
    with pytest.raises(ValueError, match="no tendons"):
        batchrun.default_ranges(scene)


def test_cli_rejects_bad_input_in_one_line(scene_file, tmp_path):
    cases = [
        (("--n", 8, "--low", "0,0"), "--low|low must be one number or one per tendon"),
        (("--n", 8, "--high", "0.01,x,0"), "--high must be comma-separated numbers"),
        (("--n", 8, "--low", 0.02, "--high", 0.01), "low must be <= high"),
        (("--n", 5, "--sampler", "grid"), "grid over 3 tendons needs n >= 2"),
    ]
    for args, message in cases:
        result = run("batch", scene_file, *args, "--out", tmp_path)
        assert result.exit_code == 1, result.output
        assert "Traceback" not in result.output
        assert any(m in result.output for m in message.split("|")), result.output
    result = run("batch", scene_file, "--n", 0, "--out", tmp_path)
    assert result.exit_code == 2 and "--n" in result.output  # usage error
    bad = tmp_path / "bad.toml"
    bad.write_text(SCENE_TOML.replace("length = 0.15", "length = -0.15"))
    result = run("batch", bad, "--n", 8, "--out", tmp_path)
    assert result.exit_code == 1 and "length" in result.output, result.output
    assert not list(tmp_path.glob("*.h5"))  # nothing was solved or written


# ------------------------------------------------------------------------------ solving


@pytest.fixture(scope="module")
def batch_run(scene_file, tmp_path_factory):
    out = tmp_path_factory.mktemp("batch")
    result = run(
        "batch",
        scene_file,
        "--n",
        8,
        "--chunk-size",
        4,
        "--high",
        0.01,
        "--seed",
        1,
        "--out",
        out,
    )
    assert result.exit_code == 0, result.output
    return out, result.output


def test_batch_writes_every_column(batch_run, scene):
    out, output = batch_run
    with h5py.File(out / "one_segment_batch.h5", "r") as f:
        shapes = {name: f[name].shape for name in f}
        data = {name: f[name][()] for name in f}
        attrs = dict(f.attrs)
        names = list(f["q"].attrs["names"])
    n, m, d = 8, scene.n_tendons, scene.n_dofs
    assert shapes == {
        "commands": (n, m),
        "q": (n, d),
        "markers": (n, 2, 3),
        "tip_position": (n, 3),
        "tip_rotation": (n, 3, 3),
        "converged": (n,),
        "stable": (n,),
        "residual_norm": (n,),
        "steps": (n,),
        "result": (n,),
    }
    assert names == list(scene.coordinate_names())
    assert attrs["rows_written"] == n and attrs["sampler"] == "lhs" and attrs["seed"] == 1
    assert attrs["scene_toml"] == SCENE_TOML
    np.testing.assert_array_equal(
        data["commands"], batchrun.sample_commands("lhs", n, np.zeros(m), np.full(m, 0.01), 1)
    )
    assert data["converged"].all() and data["stable"].all()
    assert np.all(data["residual_norm"] <= attrs["tol"])
    assert np.all(data["result"] == 0) and np.all(data["steps"] > 0)
    # The tip marker (segment 0, s = 1) is the tip position; rotations are rotations.
    np.testing.assert_allclose(data["markers"][:, 1], data["tip_position"], atol=1e-12)
    rot = data["tip_rotation"]
    np.testing.assert_allclose(
        rot @ rot.transpose(0, 2, 1), np.broadcast_to(np.eye(3), rot.shape), atol=1e-12
    )
    # Different commands, different tips; every row is the equilibrium of its command.
    assert np.ptp(data["tip_position"], axis=0).max() > 1e-3
    for i in (0, 5):
        # Recomputed under jit with the solver's kinematics: a load site known before the solve
        # is compiled in as a knot (static_load_sites). A traced site takes the other path
        # (its own Gauss-Legendre rule over [0, s]); the two agree to ~1e-9 relative in
        # position, which is ~3e-8 in this scaled residual.
        solver_scene = static_load_sites(scene)
        value = float(scaled_residual(solver_scene, data["q"][i], data["commands"][i]))
        assert value <= attrs["tol"]
        tip, _ = pj.tip_pose(scene, data["q"][i])
        np.testing.assert_allclose(tip, data["tip_position"][i], atol=1e-12)


def test_batch_summary_and_plot(batch_run):
    out, output = batch_run
    summary = json.loads((out / "one_segment_batch.json").read_text())
    assert summary["n"] == 8 and summary["converged"] == 8 and summary["chunks"] == 2
    assert summary["converged_fraction"] == 1.0
    assert summary["equilibria_per_s"] > 0 and summary["peak_memory_mib"] > 0
    assert summary["high"] == [0.01] * 3 and summary["dtype"] == "float64"
    assert (out / "one_segment_workspace.png").read_bytes()[:8] == PNG_MAGIC
    for word in ("converged 8 (100.00%)", "equilibria/s", "peak memory", "wrote"):
        assert word in output


# ------------------------------------------------------------------------------ bench
def _bench(scene_file, tmp_path, *args):
    json_path, md_path = tmp_path / "bench.json", tmp_path / "bench.md"
    result = run(
        "bench", "--scene", scene_file, "--json", json_path, "--md", md_path, "--seed", 2, *args
    )
    assert result.exit_code == 0, result.output
    return json.loads(json_path.read_text()), md_path.read_text(), result.output


def test_bench_smoke(scene_file, tmp_path):
    """The batch part alone (one chunk of 4, the compiled solver of the tests above)."""
    record, md, output = _bench(
        scene_file,
        tmp_path,
        "--batch",
        "4",
        "--dtypes",
        "float64",
        "--baseline-batch",
        0,
        "--grad-batch",
        0,
    )
    for key in ("platform", "jax", "cpu_count", "devices", "backend"):
        assert record["machine"][key], key
    (row,) = record["results"]
    assert (row["model"], row["dtype"], row["batch"]) == ("one_segment", "float64", 4)
    assert row["converged"] == 1.0 and row["max_residual_converged"] <= 1e-10
    assert row["run_s"] > 0 and row["compile_s"] >= 0
    assert row["equilibria_per_s"] == pytest.approx(4 / row["run_s"])
    assert row["vs_flow_baseline"] is None and not record["baselines"]
    assert "| one_segment | float64 | 4 |" in md and md in output


def test_bench_rejects_bad_options(scene_file, tmp_path):
    for args, message in (
        (("--models", "PAC,XYZ"), "model must be one of PCC, PAC, Poly3"),
        (("--dtypes", "float16"), "dtype must be one of float64, float32"),
        (("--batch", "0"), "batch sizes must be >= 1"),
        (("--batch", "1,x"), "--batch must be comma-separated integers"),
    ):
        result = run("bench", *args)
        assert result.exit_code == 1 and message in result.output, result.output


@pytest.mark.slow
@pytest.mark.expensive  # 17 min on a loaded 2-core machine
def test_bench_baseline_gradient_and_float32(scene_file, tmp_path):
    record, md, _ = _bench(
        scene_file, tmp_path, "--batch", "2", "--baseline-batch", 2, "--grad-batch", 2
    )
    rows = {r["dtype"]: r for r in record["results"]}
    assert set(rows) == {"float64", "float32"}
    assert rows["float32"]["tol"] == 1e-4 and rows["float32"]["converged"] == 1.0
    base = record["baselines"]["one_segment"]
    assert base["converged"] == 1.0 and base["max_residual"] <= 1e-10
    for row in rows.values():
        assert row["vs_flow_baseline"] == pytest.approx(
            row["equilibria_per_s"] / base["equilibria_per_s"]
        )
    grad = record["gradients"]["one_segment"]
    assert grad["gradient_finite"] and grad["gradient_over_forward"] > 0
    acc = record["float32_vs_float64"]["one_segment"]
    assert acc["rows_both_converged"] == 2 and acc["max_tip_difference_m"] < 1e-4
    assert "Plain-flow baseline" in md and "gradient / forward" in md
