"""What the command line says about careless input, before anything is compiled: units, headers,
typos in scene keys, missing limits named by their flags, one file name per message."""

from pathlib import Path

import pytest
from click.testing import CliRunner

from pacjax.cli.main import cli

SCENES = Path(__file__).resolve().parent.parent / "experiments" / "scenes"
TENDON_SINGLE = str(SCENES / "tendon_single.toml")


def _run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _line(result) -> str:
    lines = result.output.strip().splitlines()
    assert result.exit_code != 0 and len(lines) == 1, result.output
    return lines[0]


def test_targets_in_millimetres_read_as_metres_ask_about_units(tmp_path):
    targets = tmp_path / "mm.csv"
    targets.write_text("0,20,115\n")
    line = _line(_run("inverse", TENDON_SINGLE, targets, "--max-tension", 5))
    assert "116.7 m from the base" in line and "0.12 m long" in line and "--units" in line


def test_a_header_must_name_the_columns(tmp_path):
    targets = tmp_path / "header.csv"
    targets.write_text("a,b,c\n0,0.02,0.115\n")
    line = _line(_run("inverse", TENDON_SINGLE, targets, "--max-tension", 5))
    assert "row 1 is a header other than x,y,z" in line


def test_tension_mode_asks_for_the_cli_flag(tmp_path):
    targets = tmp_path / "t.csv"
    targets.write_text("X,Y,Z\n0,0.02,0.115\n")
    line = _line(_run("inverse", TENDON_SINGLE, targets))
    assert "--max-tension" in line and "max_tension=" not in line and "upper=" not in line


def test_units_scale_the_targets(tmp_path):
    import numpy as np

    from pacjax.cli.data import _read_targets

    path = tmp_path / "targets.csv"
    path.write_text("x,y,z\n0,20,115\n")
    np.testing.assert_allclose(_read_targets(str(path), "mm"), [[0.0, 0.02, 0.115]], rtol=1e-15)
    np.testing.assert_allclose(_read_targets(str(path), "cm"), [[0.0, 0.2, 1.15]], rtol=1e-15)


_SEGMENT = """
[model]
type = "PCC"
[[segments]]
length = 0.12
{key} = 0.02
axial_stiffness = 800.0
linear_density = 0.3
radius = 0.015
"""


def test_a_typo_in_a_required_key_is_named(tmp_path):
    scene = tmp_path / "typo.toml"
    scene.write_text(_SEGMENT.format(key="bending_stifness"))
    line = _line(_run("solve", scene))
    assert "bending_stiffness: missing required field (found 'bending_stifness'" in line


def test_an_unknown_key_gets_the_closest_valid_one(tmp_path):
    scene = tmp_path / "typo.toml"
    scene.write_text(_SEGMENT.format(key="bending_stiffness") + "radiuss = 0.01\n")
    line = _line(_run("solve", scene))
    assert "did you mean 'radius' for 'radiuss'?" in line


@pytest.mark.parametrize("command", [["solve"], ["batch", "--n", "3"], ["simulate"]], ids=str)
def test_one_file_name_per_message(tmp_path, command):
    scene = tmp_path / "neglen.toml"
    scene.write_text(_SEGMENT.format(key="bending_stiffness").replace("0.12", "-0.12"))
    line = _line(_run(*command, scene))
    assert line.count(str(scene)) == 1 and "Segment.length must be > 0" in line


@pytest.mark.parametrize(
    "command, existing",
    [
        (["solve", "{scene}"], "guess.json"),
        (["batch", "{scene}", "--n", "4", "--no-plot"], "guess_batch.h5"),
        (["simulate", "{scene}"], "guess_sim.gif"),
        (["inverse", "{scene}", "{targets}", "--max-tension", "5"], "guess_inverse.png"),
        (["fit", "{scene}", "{frames}"], "guess_fit.md"),
    ],
    ids=lambda x: x[0] if isinstance(x, list) else None,
)
def test_outputs_are_named_after_the_input_file_and_never_replaced_without_force(
    tmp_path, command, existing
):
    scene = tmp_path / "guess.toml"  # the scene inside is named "tendon_single"
    scene.write_text(Path(TENDON_SINGLE).read_text())
    targets = tmp_path / "targets.csv"
    targets.write_text("0,0.02,0.115\n")
    frames = tmp_path / "frames.csv"
    frames.write_text("# sites = [[0, 1.0]]\nu0,u1,u2,m0_x,m0_y,m0_z\n0,0,0,0,0,0.12\n")
    out = tmp_path / "out"
    out.mkdir()
    (out / existing).write_text("an earlier run")
    paths = {"scene": scene, "targets": targets, "frames": frames}
    line = _line(_run(*[a.format(**paths) for a in command], "--out", out))
    assert f"{out / existing} exists" in line and "--force" in line
    assert (out / existing).read_text() == "an earlier run"
    assert sorted(p.name for p in out.iterdir()) == [existing]


def test_outputs_take_the_input_file_name_not_the_scenes(tmp_path):
    scene = tmp_path / "guess.toml"
    scene.write_text(Path(TENDON_SINGLE).read_text())
    result = _run("solve", scene, "--out", tmp_path, "--no-plot")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "guess.json").exists() and not (tmp_path / "tendon_single.json").exists()
    again = _run("solve", scene, "--out", tmp_path, "--no-plot", "--force")
    assert again.exit_code == 0, again.output


@pytest.mark.slow  # a fit compiles batched solves and their Jacobians
def test_a_fitted_scene_solves_as_the_scene_it_was_fitted_from(tmp_path):
    """Round trip: ``pacjax fit`` with nothing to change (no iterations) writes a scene whose
    ``pacjax solve`` is the input scene's, to the last bit, controls and all."""
    import json

    import numpy as np

    import pacjax as pj
    from pacjax.io.mocapfile import save_mocap
    from pacjax.io.scenefile import load_scene

    scene, controls, _ = load_scene(TENDON_SINGLE)
    frames, _ = pj.synthetic_mocap(
        scene, np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.5]]), exact=True, noise=0.0, transform=None
    )
    save_mocap(tmp_path / "frames.csv", frames)
    fit = _run(
        "fit", TENDON_SINGLE, tmp_path / "frames.csv", "--params", "bending_stiffness",
        "--max-iterations", 0, "--holdout", 0, "--branch-starts", 0, "--no-plot",
        "--out", tmp_path,
    )  # fmt: skip
    assert fit.exit_code == 0, fit.output
    for source in (TENDON_SINGLE, tmp_path / "tendon_single_fitted.toml"):
        assert _run("solve", source, "--out", tmp_path, "--no-plot").exit_code == 0
    original = json.loads((tmp_path / "tendon_single.json").read_text())
    fitted = json.loads((tmp_path / "tendon_single_fitted.json").read_text())
    assert fitted["controls"] == original["controls"] == list(controls)
    assert fitted["q"] == original["q"]
    assert fitted["tip"] == original["tip"]


def test_progress_in_a_log_is_a_line_every_interval():
    import io

    from pacjax.cli.common import Progress

    log = io.StringIO()
    with Progress(1000, "batch", interval=0.0, file=log) as bar:
        bar.update(0)
        bar.update(250)
    lines = log.getvalue().splitlines()
    assert lines[0] == "batch: 0/1000 eq"
    assert lines[1].startswith("batch: 250/1000 eq (25 %), ") and lines[1].endswith(" left")
    assert " eq/s, " in lines[1]


def test_progress_on_a_terminal_is_a_bar_with_one_unit():
    import io

    from pacjax.cli.common import Progress

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    screen = Terminal()
    with Progress(10, "batch", file=screen) as bar:
        bar.update(3)
    assert bar.bar is not None and bar.bar.unit == "eq" and bar.bar.n == 3
    assert "batch" in screen.getvalue()


def test_the_batch_reports_rows_as_they_leave_the_pool():
    import numpy as np

    import pacjax as pj
    from pacjax.io.scenefile import load_scene

    scene, _, _ = load_scene(TENDON_SINGLE)
    commands = np.random.default_rng(0).uniform(0.0, 4.0, (300, 3))
    counts = []
    chunks = list(pj.iter_batch(scene, commands, chunk_size=300, on_rows=counts.append))
    assert len(chunks) == 1 and sum(counts) == 300
    assert len(counts) > 2  # several times within the one chunk


def test_a_batch_without_a_terminal_logs_its_progress(tmp_path, monkeypatch):
    from pacjax.cli import common

    monkeypatch.setattr(common, "LOG_INTERVAL", 0.0)  # a line at every update
    result = CliRunner().invoke(
        cli, ["batch", TENDON_SINGLE, "--n", "16", "--chunk-size", "8", "--out", str(tmp_path)]
    )
    assert result.exit_code == 0, result.output
    lines = [line for line in result.output.splitlines() if line.startswith("batch: ")]
    assert lines and lines[-1].startswith("batch: 16/16 eq (100 %), ")
    assert all(" eq" in line for line in lines)
