"""One result enumeration: every solve's result has ``.result`` in ``pj.RESULTS`` and
``.successful``; the attributes they replace still work, with a DeprecationWarning."""

import dataclasses

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pacjax as pj
from pacjax._dynamics.simulate import _result as trajectory_result
from pacjax._inverse.results import inverse_result
from pacjax._results import code_of, describe, from_code


def _scene(model=None):
    segment = pj.Segment(0.12, 0.02, 800.0, linear_density=0.3, radius=0.015)
    robot = pj.Robot((segment,), base_rotation=np.diag([1.0, -1.0, -1.0]))
    tendon = pj.Tendon(0, np.pi / 2, 0.012, gain=5e3, guides=(0.0, 0.5, 1.0))
    return pj.Scene(
        robot,
        model or pj.PCC(),
        tendons=(tendon,),
        loads=(pj.Gravity(), pj.PointMass(0.05, 0, 1.0)),
        quadrature_points=4,
    )


SCENE = _scene()


def test_codes_round_trip_and_messages():
    codes = jnp.arange(len(pj.RESULTS))
    items = from_code(codes)
    np.testing.assert_array_equal(code_of(items), np.arange(len(pj.RESULTS)))
    assert bool(from_code(0) == pj.RESULTS.successful)
    assert describe(pj.RESULTS.stalled, "ok") == pj.RESULTS[pj.RESULTS.stalled]
    assert describe(from_code(jnp.array([0, 3])), "ok") == ["ok", pj.RESULTS[pj.RESULTS.stalled]]
    # traceable: the item survives jit and vmap
    assert bool(jax.jit(from_code)(2) == pj.RESULTS.nonfinite)
    np.testing.assert_array_equal(
        jax.vmap(from_code)(jnp.array([0, 1])) == pj.RESULTS.successful, [True, False]
    )


def test_equilibrium_and_batch_results():
    eq = pj.solve_equilibrium(SCENE, jnp.array([0.004]))
    assert isinstance(eq.result, pj.RESULTS)
    assert bool(eq.successful) and bool(eq.converged) and eq.reason == "converged"
    # a step limit too small to converge: not successful, and the reason says why
    short = pj.solve_equilibrium(SCENE, jnp.array([0.004]), max_steps=1, escapes=0, fallback=False)
    assert not bool(short.successful)
    assert bool(short.result == pj.RESULTS.max_steps_reached), short.reason
    batch = pj.solve_batch(SCENE, np.array([[0.0], [0.004]]))
    assert isinstance(batch.result, pj.RESULTS)
    np.testing.assert_array_equal(np.asarray(batch.successful), np.asarray(batch.converged))
    assert batch.reason == ["converged", "converged"]


def test_equilibria_result():
    found = pj.find_equilibria(SCENE, jnp.array([0.004]), n_starts=4, seed=0)
    assert isinstance(found.result, pj.RESULTS)
    assert found.successful and bool(found.result == pj.RESULTS.successful)


def test_inverse_result_codes_and_deprecated_code():
    reached = np.array([True, False, False])
    converged = np.array([True, True, False])
    result = inverse_result(reached, converged)
    want = [pj.RESULTS.successful, pj.RESULTS.target_not_reached, pj.RESULTS.no_equilibrium]
    for i, item in enumerate(want):
        assert bool(np.asarray(result == item)[i])
    n = 3
    res = pj.InverseResult(
        controls=jnp.zeros((n, 1)),
        q=jnp.zeros((n, 3)),
        error=jnp.zeros(n),
        orientation_error=jnp.zeros(n),
        reached=jnp.asarray(reached),
        position=jnp.zeros((n, 3)),
        rotation=jnp.zeros((n, 3, 3)),
        tensions=jnp.zeros((n, 1)),
        iterations=jnp.zeros(n, int),
        starts=jnp.ones(n, int),
        converged=jnp.asarray(converged),
        result=result,
    )
    np.testing.assert_array_equal(np.asarray(res.successful), reached)
    assert res.message[0] == "target reached" and "not reached" in res.message[1]
    with pytest.warns(DeprecationWarning, match="InverseResult.code"):
        codes = res.code
    np.testing.assert_array_equal(
        np.asarray(codes), [pj.inverse.REACHED, pj.inverse.NOT_REACHED, pj.inverse.NO_EQUILIBRIUM]
    )
    tracking = pj.Tracking(res, max_command_jump=0.0, seconds=1.0, waypoints_per_second=3.0)
    np.testing.assert_array_equal(np.asarray(tracking.successful), reached)
    assert isinstance(tracking.result, pj.RESULTS)


def test_trajectory_result_from_diffrax():
    for theirs, ours in [
        (diffrax.RESULTS.successful, pj.RESULTS.successful),
        (diffrax.RESULTS.max_steps_reached, pj.RESULTS.max_steps_reached),
        (diffrax.RESULTS.dt_min_reached, pj.RESULTS.integration_failed),
    ]:
        assert bool(trajectory_result(theirs) == ours)


def test_deprecated_trajectory_success_and_report_converged():
    traj = pj.Trajectory(
        ts=jnp.zeros(1),
        q=jnp.zeros((1, 3)),
        qdot=jnp.zeros((1, 3)),
        result=pj.RESULTS.successful,
        num_steps=jnp.asarray(1),
        num_accepted_steps=jnp.asarray(1),
    )
    assert bool(traj.successful)
    with pytest.warns(DeprecationWarning, match="Trajectory.success"):
        assert bool(traj.success)
    fields = {f.name: None for f in dataclasses.fields(pj.IdentificationReport)}
    report = pj.IdentificationReport(**{**fields, "result": pj.RESULTS.max_steps_reached})
    assert not report.successful
    with pytest.warns(DeprecationWarning, match="IdentificationReport.converged"):
        assert not report.converged


@pytest.mark.long(minutes=1.4)
@pytest.mark.slow
def test_each_workflow_reports_a_result():
    """A real inverse solve, a tracked path, a simulation and a fit, each with ``.result`` in
    ``pj.RESULTS`` and ``.successful``."""
    tip = pj.tip_pose(SCENE, pj.solve_equilibrium(SCENE, jnp.array([0.003])).q)[0]
    inv = pj.inverse_statics(SCENE, np.asarray(tip))
    assert isinstance(inv.result, pj.RESULTS) and bool(inv.successful), inv.message
    path = pj.track(SCENE, np.stack([np.asarray(tip)] * 2))
    assert isinstance(path.result, pj.RESULTS) and bool(np.all(path.successful))
    traj = pj.simulate(SCENE, (0.0, 0.01), controls=jnp.array([0.003]))
    assert isinstance(traj.result, pj.RESULTS) and bool(traj.successful)
    data, _ = pj.synthetic_mocap(SCENE, np.array([[0.0], [0.002], [0.004]]), sites=((0, 1.0),))
    _, report = pj.identify(SCENE, data, params=("bending_stiffness",))
    assert isinstance(report.result, pj.RESULTS) and report.successful, report.message


def test_a_converged_saddle_is_flagged_not_successful():
    # A heavy column standing upright: straight is an equilibrium, and an unstable one.
    seg = pj.Segment(0.5, 2e-4, 1e3, linear_density=0.2, extensible=False)
    scene = pj.Scene(pj.Robot([seg]), pj.PolynomialCurvature(1), loads=[pj.Gravity()])
    eq = pj.solve_equilibrium(scene, escapes=0, fallback=False)
    assert bool(eq.converged) and not bool(eq.stable)
    assert float(eq.min_hessian_eigenvalue) < 0
    assert bool(eq.result == pj.RESULTS.converged_saddle) and not bool(eq.successful)
    assert "unstable equilibrium" in eq.reason
    # With its escapes (the default) the solve leaves the saddle for the buckled minimum.
    buckled = pj.solve_equilibrium(scene, fallback=False)
    assert bool(buckled.successful) and bool(buckled.stable), buckled.reason
