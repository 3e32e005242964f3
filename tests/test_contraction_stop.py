"""The contraction stop of a segment: a modelled end of range, never an overflow (issue 6).

Cheap checks on the energy alone (nothing is solved here); the solve that pulls the tendons past
the end of the range is in ``tests/test_extreme_cases.py`` (CI's slow step).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pacjax as pj
from pacjax._model.energy import STOP_BAND, contraction_stop_energy

LIMIT = 0.07  # m, the paper robot's range
K_A = 1078.0  # N/m
WIDTH = STOP_BAND * LIMIT
ONSET = LIMIT - WIDTH  # contraction where the stop starts to act


def _stop(contraction):
    return contraction_stop_energy(-jnp.asarray(contraction), LIMIT, K_A)


def test_no_energy_force_or_stiffness_before_the_contact_band():
    values = jax.jit(jax.vmap(lambda c: (_stop(c), jax.grad(_stop)(c), jax.hessian(_stop)(c))))
    for value in values(jnp.asarray([-0.05, 0.0, 0.03, ONSET])):
        np.testing.assert_array_equal(value, 0.0)


def test_twice_differentiable_at_the_onset_of_contact():
    """Value, force and stiffness all start from zero: no kink for Newton steps."""
    h = 1e-9
    assert float(_stop(ONSET + h)) < 1e-20
    assert abs(float(jax.grad(_stop)(ONSET + h))) < 1e-9
    assert abs(float(jax.hessian(_stop)(ONSET + h))) < 1e-5 * K_A  # vs the spring k_a


def test_force_matches_its_closed_form_and_grows_without_bound():
    depths = np.array([0.1, 0.5, 0.9, 0.99, 0.999])
    forces = np.array([float(jax.grad(_stop)(ONSET + x * WIDTH)) for x in depths])
    expected = K_A * WIDTH * depths**2 * (3 - 2 * depths) / (1 - depths) ** 2
    np.testing.assert_allclose(forces, expected, rtol=1e-9)
    assert np.all(np.diff(forces) > 0) and forces[-1] > 1e4  # N: more than any tendon here
    grad = jax.grad(_stop)(ONSET + 0.5 * WIDTH)
    fd = (_stop(ONSET + 0.5 * WIDTH + 1e-9) - _stop(ONSET + 0.5 * WIDTH - 1e-9)) / 2e-9
    assert float(grad) == pytest.approx(float(fd), rel=1e-5)


def test_infinite_at_and_past_the_limit():
    for c in (LIMIT, LIMIT + 1e-9, 0.2, 1.0):
        assert float(_stop(c)) == np.inf


def test_scene_energy_is_infinite_past_a_segment_s_limit_and_finite_before():
    seg = pj.Segment(0.1, 0.01, 1000.0, contraction_limit=0.04)
    scene = pj.Scene(pj.Robot([seg, seg]), pj.PCC())
    q = np.zeros(scene.n_dofs)
    q[2] = -0.039  # inside the band of segment 0
    energy_and_grad = jax.jit(jax.value_and_grad(lambda q: scene.potential_energy(q, jnp.zeros(0))))
    energy, grad = energy_and_grad(jnp.asarray(q))
    assert np.isfinite(float(energy)) and np.all(np.isfinite(np.asarray(grad)))
    assert float(grad[2]) < -1000 * 0.039  # the stop pushes back beyond the spring alone
    q[5] = -0.041  # segment 1 past its stop
    assert float(energy_and_grad(jnp.asarray(q))[0]) == np.inf


def test_the_paper_robot_stops_at_its_70_mm_range():
    scene = pj.presets.stella2023()
    limits = [float(seg.contraction_limit) for seg in scene.robot.segments]
    assert limits == [pytest.approx(0.070)] * 3


def test_known_start_closed_over_by_a_jitted_function():
    """A concrete ``q0`` inside a ``jax.jit`` trace is still checked on the host (it used to
    fail with a TracerArrayConversionError in the contraction check), and a start past the
    contraction stop is still refused, at trace time."""
    segment = pj.Segment(0.1, 0.01, 100.0)
    scene = pj.Scene(pj.Robot([segment]), pj.PolynomialCurvature(1))
    q0 = jnp.zeros(scene.n_dofs).at[0].set(0.1)
    q = jax.jit(lambda: pj.solve_equilibrium(scene, None, q0).q)()
    np.testing.assert_allclose(q, pj.solve_equilibrium(scene, None, q0).q, atol=1e-12)
    past = q0.at[-1].set(-0.095)  # dL beyond the default limit (90 % of 0.1 m)
    with pytest.raises(ValueError, match="contraction_limit"):
        jax.jit(lambda: pj.solve_equilibrium(scene, None, past).q)()
