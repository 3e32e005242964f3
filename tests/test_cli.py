"""The command line: demo, solve, and one-line errors for bad input."""

import json
import pathlib

import numpy as np
import pytest
from click.testing import CliRunner

from pacjax import plots
from pacjax.cli.main import DEMO_COMMANDS, cli
from pacjax.io.scenefile import load_scene

SCENES = pathlib.Path(__file__).resolve().parent.parent / "experiments" / "scenes"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def test_help():
    result = run("--help")
    assert result.exit_code == 0
    assert "demo" in result.output and "solve" in result.output


@pytest.mark.slow  # the whole demo, compiled (37 s): CI's slow step
def test_demo_writes_figure_and_table(tmp_path):
    result = run("demo", "--out", tmp_path)
    assert result.exit_code == 0, result.output
    png = tmp_path / "demo.png"
    assert png.read_bytes()[:8] == PNG_MAGIC
    out = result.output
    for word in ("command", "tip x", "PAC-PCC", "residual", "steps", "ms", "compilation"):
        assert word in out
    for command in DEMO_COMMANDS:
        assert sum(line.startswith(command) for line in out.splitlines()) >= 2, command
    # every solve converged to a stable equilibrium
    table = [line for line in out.splitlines() if line[17:22].strip() in ("PCC", "PAC")]
    assert len(table) == 2 * len(DEMO_COMMANDS), table
    assert all(" NO " not in line for line in table), table


def test_solve_writes_json_and_png(tmp_path):
    scene_file = SCENES / "tendon_single.toml"
    result = run("solve", scene_file, "--out", tmp_path)
    assert result.exit_code == 0, result.output
    data = json.loads((tmp_path / "tendon_single.json").read_text())
    assert (tmp_path / "tendon_single.png").read_bytes()[:8] == PNG_MAGIC
    scene, controls, _ = load_scene(scene_file)
    assert data["converged"] is True and data["stable"] is True
    assert data["reason"] == "converged"
    assert len(data["q"]) == scene.n_dofs
    assert data["controls"] == list(controls)
    assert data["tendon_tensions"] == pytest.approx(list(controls))  # tension mode
    assert len(data["markers"]["positions"]) == len(scene.markers)
    assert np.allclose(data["markers"]["positions"][-1], data["tip"]["position"])
    rotation = np.asarray(data["tip"]["rotation"])
    assert np.allclose(rotation.T @ rotation, np.eye(3))
    for key in ("residual_norm", "min_hessian_eigenvalue", "steps"):
        assert key in data
    assert "tip position" in result.output


def test_solve_controls_override(tmp_path):
    result = run(
        "solve",
        SCENES / "tendon_single.toml",
        "--controls",
        "0,2.5,0",
        "--out",
        tmp_path,
        "--no-plot",
    )
    assert result.exit_code == 0, result.output
    data = json.loads((tmp_path / "tendon_single.json").read_text())
    assert data["controls"] == [0.0, 2.5, 0.0]
    assert not (tmp_path / "tendon_single.png").exists()
    # tendon 1 sits at 210 degrees: the tip moves towards -y
    assert data["tip"]["position"][1] < 0


@pytest.mark.slow  # compiles the dynamics for one segment
def test_simulate_settles_on_the_solve_and_writes_its_files(tmp_path):
    """A step in tendon tensions, damped at the critical ratio of the lowest mode: after 1 s
    at the default tolerances the tip is where `pacjax solve` puts it (within a micrometre),
    from 12.9 mm away.
    With the damping matrix fixed at the straight rest state (``K_0``), the bending-plane angle
    of the bent segment was undamped: the tip still swung by 0.03-0.3 mm after 2 s."""
    scene_file = SCENES / "tendon_single.toml"
    result = run(
        "simulate", scene_file, "--duration", "1.0", "--damping-ratio", "1.0", "--fps", "10",
        "--out", tmp_path,
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    data = json.loads((tmp_path / "tendon_single_sim.json").read_text())
    assert data["success"] is True
    assert (data["rtol"], data["atol"]) == (1e-4, 1e-6)  # pj.simulate's defaults
    assert data["t"] == pytest.approx(np.linspace(0.0, 1.0, 11).tolist())
    assert (tmp_path / "tendon_single_tip.png").read_bytes()[:8] == PNG_MAGIC
    assert (tmp_path / "tendon_single_sim.gif").read_bytes()[:6] in (b"GIF87a", b"GIF89a")
    tips = np.asarray(data["tip_position"])
    assert tips.shape == (11, 3)
    # it moves: the start is the equilibrium under zero controls
    assert np.linalg.norm(tips[-1] - tips[0]) > 5e-3
    assert run("solve", scene_file, "--out", tmp_path).exit_code == 0
    solved = json.loads((tmp_path / "tendon_single.json").read_text())
    assert np.linalg.norm(tips[-1] - np.asarray(solved["tip"]["position"])) < 1e-6


@pytest.mark.parametrize(
    "args, code, message",
    [
        (["solve", "missing.toml"], 2, "does not exist"),
        (["solve", "{bad}"], 1, "not valid TOML"),
        (["solve", "{scene}", "--controls", "0.01,0"], 1, "2 value(s) but the scene has 3"),
        (["solve", "{scene}", "--controls", "a,b,c"], 1, "comma-separated numbers"),
        (["solve", "{scene}", "--controls", "-1,0,0"], 1, "must be >= 0"),
        (["solve", "{broken}"], 1, "tendons[0].segment: segment 5 does not exist"),
        (["nonsense"], 2, "No such command"),
        (["simulate", "{scene}", "--controls", "0.01,0"], 1, "2 value(s) but the scene has 3"),
        (["simulate", "{broken}"], 1, "tendons[0].segment: segment 5 does not exist"),
        (["simulate", "{scene}", "--duration", "0"], 2, "Invalid value for '--duration'"),
        (["simulate", "{scene}", "--rtol", "0"], 2, "Invalid value for '--rtol'"),
    ],
)
def test_bad_input_one_line_no_traceback(tmp_path, args, code, message):
    bad = tmp_path / "bad.toml"
    bad.write_text("[[segments]\n")
    broken = tmp_path / "broken.toml"
    text = (SCENES / "tendon_single.toml").read_text()
    broken.write_text(
        text.replace("segment = 0\nangle_deg = 90.0", "segment = 5\nangle_deg = 90.0")
    )
    paths = {"bad": bad, "broken": broken, "scene": SCENES / "tendon_single.toml"}
    args = [a.format(**paths) for a in args]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == code, result.output
    assert message in result.output
    assert "Traceback" not in result.output
    assert not isinstance(result.exception, (ValueError, TypeError))
    error_lines = [line for line in result.output.splitlines() if line.startswith("Error")]
    assert len(error_lines) == 1


def test_plot_helpers(tmp_path):
    import pacjax as pj

    scene, controls, _ = load_scene(SCENES / "tendon_single.toml")
    eq = pj.solve_equilibrium(scene, controls)
    fig = plots.plot_equilibria(
        scene,
        [eq, np.zeros(scene.n_dofs)],
        tmp_path / "two.png",
        title="two cases",
        targets={"measured": [[0.0, 0.01, 0.11]]},
        views=("3d", "xy"),
    )
    assert (tmp_path / "two.png").read_bytes()[:8] == PNG_MAGIC
    assert len(fig.axes) == 2
    with pytest.raises(ValueError, match="coordinates"):
        plots.plot_equilibria(scene, np.zeros(5), tmp_path / "x.png")
    with pytest.raises(ValueError, match="view"):
        plots.plot_equilibria(scene, eq, tmp_path / "x.png", views=("front",))
