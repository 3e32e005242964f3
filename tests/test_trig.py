"""Sines and cosines as fused arithmetic (pacjax._model.trig), and the dynamics' use of them."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pacjax as pj
from pacjax._dynamics.simulate import prepare
from pacjax._model.trig import sin_cos_versine, sincos


def _angles():
    rng = np.random.default_rng(0)
    return np.concatenate(
        [
            rng.uniform(-20.0, 20.0, 20_000),
            np.linspace(-1e4, 1e4, 20_001),
            [0.0, 1e-300, -1e-300, 5e-324, math.pi, math.pi / 2, -math.pi / 2, 1e5, 1e6],
        ]
    )


def test_float64_sine_and_cosine_match_the_library_to_rounding():
    x = _angles()
    s, c = jax.jit(sincos)(jnp.asarray(x))
    assert np.max(np.abs(np.asarray(s) - np.sin(x))) <= 2.3e-16
    assert np.max(np.abs(np.asarray(c) - np.cos(x))) <= 2.3e-16
    # Tiny angles keep their relative precision (sin x = x).
    tiny = np.array([1e-300, -1e-200, 1e-20])
    assert np.array_equal(np.asarray(sincos(jnp.asarray(tiny))[0]), tiny)


def test_non_finite_angles_give_nan():
    s, c = sincos(jnp.asarray([np.inf, -np.inf, np.nan]))
    assert np.all(np.isnan(np.asarray(s))) and np.all(np.isnan(np.asarray(c)))


def test_float32_takes_the_library_forms():
    x = jnp.asarray(_angles()[:1000], jnp.float32)
    s, c = sincos(x)
    assert s.dtype == jnp.float32
    np.testing.assert_array_equal(np.asarray(s), np.asarray(jnp.sin(x)))
    np.testing.assert_array_equal(np.asarray(c), np.asarray(jnp.cos(x)))


@pytest.mark.parametrize("x", [0.0, 0.3, -2.5, 7.0])
def test_first_and_second_derivatives(x):
    x = jnp.asarray(x)
    assert float(jax.grad(lambda t: sincos(t)[0])(x)) == pytest.approx(math.cos(x), abs=1e-15)
    assert float(jax.grad(lambda t: sincos(t)[1])(x)) == pytest.approx(-math.sin(x), abs=1e-15)
    second = jax.hessian(lambda t: sincos(t)[0])(x)
    assert float(second) == pytest.approx(-math.sin(x), abs=1e-15)
    st, ct, vers = sin_cos_versine(x, sincos)
    assert float(st) == pytest.approx(math.sin(x), abs=1e-15)
    assert float(ct) == pytest.approx(math.cos(x), abs=1e-15)
    assert float(vers) == pytest.approx(1.0 - math.cos(x), abs=1e-15)


@pytest.mark.parametrize("model", [pj.PAC(), pj.PCC(frame="paper")])
def test_a_model_with_fused_trig_is_the_same_model_to_rounding(model):
    scene = pj.presets.stella2023(model, tip_mass=0.2)
    fused = pj.Scene(
        scene.robot, model.with_fused_trig(), scene.tendons, scene.loads, scene.markers
    )
    q = 0.3 * jnp.sin(jnp.arange(scene.n_dofs, dtype=jnp.float64) + 1.0)
    controls = jnp.full(scene.n_tendons, 0.01)

    @jax.jit  # one program per scene: evaluated op by op, the kinematics take seconds
    def tip_and_residual(q):
        return [(pj.tip_pose(s, q), s.residual(q, controls)) for s in (scene, fused)]

    (tip_a, ra), (tip_b, rb) = tip_and_residual(q)
    for a, b in zip(tip_a, tip_b, strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(ra), np.asarray(rb), rtol=1e-12, atol=1e-12)


def test_the_dynamics_takes_fused_trig_and_the_statics_does_not():
    scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
    assert not scene.model.fused_trig
    prepared = prepare(scene, 0.0, 0.01, None, None, None, 1e-4, 1e-6, 100, False, 1.0, None)[0]
    assert prepared.model.fused_trig and isinstance(prepared.model, pj.PAC)
