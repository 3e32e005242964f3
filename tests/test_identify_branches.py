"""Identification on the data's equilibrium branches (issue 27, item 3): a hanging cable with a
tip mass, curled by a tendon, has two stable equilibria under one tension (a mild bend and a
loop curled through more than a turn); data recorded on the loop must not be fitted on the bend.
"""

import equinox as eqx
import numpy as np
import pytest

import pacjax as pj
from pacjax._identify.branches import BranchTracker

EI = 9e-4  # N m^2


def cable(ei=EI):
    seg = pj.Segment(0.3, ei, 1e3, linear_density=1e-3, extensible=False)
    return pj.Scene(
        pj.Robot([seg], base_rotation=pj.presets.MOUNTS["hanging"]),
        pj.PCC(),
        tendons=[pj.Tendon(0, 0.0, 0.01, mode="tension", routing="channel")],
        loads=[pj.Gravity(), pj.PointMass(0.05, 0)],
        markers=[(0, 0.25), (0, 0.5), (0, 0.75), (0, 1.0)],
    )


@pytest.fixture(scope="module")
def curled():
    """Six frames (1-3 N) recorded on the curled branch (7.1-8.1 rad of bending)."""
    tensions = np.linspace(1.0, 3.0, 6)[:, None]
    data, truth = pj.synthetic_mocap(
        cable(), tensions, exact=True, noise=1e-3, transform=None, q0=np.array([7.5, 0.0])
    )
    assert np.all(truth.q[:, 0] > 7.0)  # the loop: the solve from straight gives < 1 rad
    return data


@pytest.mark.slow  # fits compile batched solves and their Jacobians
def test_a_fit_started_off_the_datas_branch_moves_there_and_recovers_ei(curled):
    # Without the checks the frames stay on the bend, where no stiffness fits the loop: the
    # fit drives EI into its bound (the trap the checks exist for).
    trapped, report = pj.identify(cable(2 * EI), curled, branch_starts=0, progress=False)
    assert report.train.rmse_mm > 50.0
    assert report.parameters["bending_stiffness"]["at_bound"] == ["lower"]

    fitted, report = pj.identify(cable(2 * EI), curled, progress=False)
    assert report.successful, report.message
    assert report.branches.switched.all()
    assert not report.branches.off_branch.any()
    assert (report.branches.alternatives >= 1).all()
    value = float(fitted.robot.segments[0].bending_stiffness)
    std = report.parameters["bending_stiffness"]["std"][0]
    assert abs(value / EI - 1) < 0.03
    assert abs(value - EI) < 3 * std
    assert report.train.rmse_mm < 2.5  # 1 mm noise per coordinate: sqrt(3) mm expected
    summary = report.to_dict()["branches"]
    assert summary["frames_switched"] == list(range(curled.n_frames))
    assert "Moved to a branch that fits the data better" in report.to_markdown()


@pytest.mark.slow
def test_a_step_over_a_fold_is_a_jump_and_a_small_step_is_not(curled):
    """The loop at 3 N ends at a fold between 1x and 8x the true EI: the warm-started solve
    beyond it lands on the bend, which the step's linearisation does not predict."""
    fit_scene = cable()
    from pacjax._identify.identify import _batch_settings, _build_problem

    fit = _build_problem(fit_scene, curled, None, ("bending_stiffness",), (), None, (1e-3, 1, None))
    chunk, options = _batch_settings(16, None)
    train = fit.evaluator(curled, chunk, options)
    tracker = BranchTracker(fit.problem.scene, curled.markers, 1e-3, 0, 0)
    loop = np.zeros((16, 2))
    loop[:, 0] = 7.5
    current = train(np.zeros(1), q0=loop)
    assert current.valid[: curled.n_frames].all()
    small = train(np.array([0.05]), q0=current.q)
    assert not tracker.jumped(current, small, np.array([0.05])).any()
    big = np.array([np.log(8.0)])
    beyond = train(big, q0=current.q)
    jumped = tracker.jumped(current, beyond, big)
    assert jumped[-1]  # the most loaded frame left the loop
    assert np.all(np.asarray(beyond.q)[: curled.n_frames][jumped, 0] < 3.0)


@pytest.mark.slow
def test_stages_and_several_starts_are_reported(curled):
    start = eqx.tree_at(lambda s: s.tendons[0].offset, cable(2 * EI), 0.012)
    fitted, report = pj.identify(
        start,
        curled,
        stages=[["bending_stiffness"], ["bending_stiffness", "tendon_offset"]],
        n_starts=2,
        progress=False,
    )
    assert [s["params"] for s in report.stages] == [
        ["bending_stiffness"],
        ["bending_stiffness", "tendon_offset"],
    ]
    assert report.successful, report.message
    assert len(report.starts) == 2  # the last stage's descents
    assert report.stages[1]["rmse_mm"] <= report.stages[0]["rmse_mm"] + 1e-9
    assert abs(float(fitted.tendons[0].offset) / 0.01 - 1) < 0.05
    assert abs(float(fitted.robot.segments[0].bending_stiffness) / EI - 1) < 0.05
    assert len(report.loss_history) == len(report.rmse_history_mm)
    text = report.to_markdown()
    assert "## Stages" in text and "## Starts" in text


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"n_starts": 0}, "n_starts must be >= 1"),
        ({"branch_starts": -1}, "branch_starts must be >= 0"),
        ({"stages": []}, "stages must be a non-empty list"),
        ({"stages": [["bending_stiffness"], []]}, "stages must be a non-empty list"),
    ],
)
def test_bad_strategy_arguments_are_one_line_errors(kwargs, message):
    markers = np.random.default_rng(0).normal(size=(2, 4, 3))
    data = pj.MocapDataset.from_arrays([[1.0], [2.0]], markers, cable().markers)
    with pytest.raises(ValueError, match=message):
        pj.identify(cable(), data, progress=False, **kwargs)


def test_cli_fit_checks_every_stage_before_fitting(tmp_path):
    from click.testing import CliRunner

    from pacjax.cli.main import cli
    from pacjax.io.mocapfile import save_mocap
    from pacjax.io.scenefile import save_scene

    markers = np.random.default_rng(0).normal(scale=0.1, size=(2, 4, 3))
    save_mocap(
        tmp_path / "d.csv", pj.MocapDataset.from_arrays([[1.0], [2.0]], markers, cable().markers)
    )
    save_scene(tmp_path / "c.toml", cable(), name="c")
    result = CliRunner().invoke(
        cli,
        [
            "fit",
            str(tmp_path / "c.toml"),
            str(tmp_path / "d.csv"),
            "--no-plot",
            "--holdout",
            "0",
            "--stages",
            "bending_stiffness;bending_stiffness,stiffnes",
            "--out",
            str(tmp_path),
        ],
    )
    assert result.exit_code == 1
    assert "stages[1]: unknown parameter 'stiffnes'" in result.output
    assert len(result.output.strip().splitlines()) == 1
