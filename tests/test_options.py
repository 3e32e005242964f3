"""One options object: ``pj.SolverOptions`` is taken by every solve, keyword overrides of its
fields too, and an unknown option fails naming it and the valid ones, before any compilation."""

import numpy as np
import pytest

import pacjax as pj
import pacjax._statics.batch as batch_module
import pacjax._statics.equilibrium as equilibrium_module


def _scene():
    segment = pj.Segment(0.12, 0.02, 800.0, linear_density=0.3, radius=0.015)
    robot = pj.Robot((segment,), base_rotation=np.diag([1.0, -1.0, -1.0]))
    tendon = pj.Tendon(0, np.pi / 2, 0.012, gain=5e3, guides=(0.0, 0.5, 1.0))
    return pj.Scene(robot, pj.PCC(), tendons=(tendon,), loads=(pj.Gravity(),), quadrature_points=4)


SCENE = _scene()
U = np.array([0.004])


@pytest.fixture
def no_solver(monkeypatch):
    """Fail if anything reaches the (compiled) solver."""

    def spy(*args, **kwargs):
        raise AssertionError("the solver was reached: the options were not rejected beforehand")

    monkeypatch.setattr(equilibrium_module, "_solve_checked", spy)
    monkeypatch.setattr(batch_module, "_solve_chunk", spy)
    monkeypatch.setattr(batch_module, "pool_solve", spy)


CALLS = {
    "solve_equilibrium": lambda **kw: pj.solve_equilibrium(SCENE, U, **kw),
    "solve_batch": lambda **kw: pj.solve_batch(SCENE, U[None], **kw),
    "iter_batch": lambda **kw: list(pj.iter_batch(SCENE, U[None], **kw)),
    "find_equilibria": lambda **kw: pj.find_equilibria(SCENE, U, **kw),
}


@pytest.mark.parametrize("name", sorted(CALLS))
def test_an_unknown_option_names_itself_and_the_valid_ones(name, no_solver):
    with pytest.raises(TypeError, match=r"unknown solver option tolerance; valid options: tol,"):
        CALLS[name](tolerance=1e-8)


@pytest.mark.parametrize("name", sorted(CALLS))
def test_options_must_be_solver_options(name, no_solver):
    with pytest.raises(TypeError, match="options must be a pacjax.SolverOptions, got dict"):
        CALLS[name](options={"tol": 1e-8})


def test_workflows_reject_bad_options_before_solving(no_solver):
    target = np.array([0.0, 0.0, -0.1])
    for call in (
        lambda **kw: pj.inverse_statics(SCENE, target, **kw),
        lambda **kw: pj.inverse_statics_batch(SCENE, target[None], **kw),
        lambda **kw: pj.track(SCENE, target[None], **kw),
        lambda **kw: pj.sample_workspace(SCENE, 4, **kw),
    ):
        with pytest.raises(TypeError, match="options must be a pacjax.SolverOptions"):
            call(options={"tol": 1e-8})
        with pytest.warns(DeprecationWarning, match="solver_options"):
            with pytest.raises(TypeError, match="unknown solver option tolerance"):
                call(solver_options={"tolerance": 1e-8})
    data = pj.MocapDataset.from_arrays(U[None], np.zeros((1, 1, 3)), sites=((0, 1.0),))
    with pytest.raises(TypeError, match="options must be a pacjax.SolverOptions"):
        pj.identify(SCENE, data, options={"tol": 1e-8})


@pytest.mark.slow  # five solves with options of their own, each compiled (37 s): CI's slow step
def test_options_object_and_overrides_reach_the_solver():
    loose = pj.SolverOptions(tol=1e-4)
    one = pj.solve_equilibrium(SCENE, U, options=loose)
    tight = pj.solve_equilibrium(SCENE, U, options=loose, tol=1e-12)
    assert bool(one.converged) and float(one.residual_norm) <= 1e-4
    assert bool(tight.converged) and float(tight.residual_norm) <= 1e-12
    assert int(tight.steps) >= int(one.steps)
    # a step limit of 1 cannot converge, with the object or the override
    capped = pj.SolverOptions(max_steps=1, escapes=0)
    assert not bool(pj.solve_equilibrium(SCENE, U, options=capped, fallback=False).converged)
    assert not bool(
        np.all(pj.solve_batch(SCENE, U[None], options=capped, fallback=False).converged)
    )
    batch = pj.solve_batch(SCENE, np.stack([U, 2 * U]), options=loose, tol=1e-12)
    assert np.all(np.asarray(batch.residual_norm) <= 1e-12)


def test_the_first_pseudo_time_step_defaults_per_coordinates():
    from pacjax._statics.equilibrium import make_solver
    from pacjax._statics.options import POLAR_INITIAL_DT, resolve_options

    options = resolve_options(dtype=np.float64)
    assert options.initial_dt is None
    for model, expected in [
        (pj.PAC(), POLAR_INITIAL_DT),
        (pj.PCC(), POLAR_INITIAL_DT),
        (pj.PolynomialCurvature(1), 1.0),
    ]:
        scene = pj.presets.stella2023(model, n_sections=1)
        assert make_solver(scene, options, np.float64).initial_dt == expected
        given = resolve_options(options, initial_dt=5.0)
        assert make_solver(scene, given, np.float64).initial_dt == 5.0
