"""XLA:CPU compile options of the solver's programs (pacjax._jit)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pacjax as pj
from pacjax import _jit


@pytest.fixture
def fresh_options():
    _jit.compile_options.cache_clear()
    yield
    _jit.compile_options.cache_clear()


def test_options_apply_on_cpu_unless_xla_flags_sets_them_or_xla_lacks_them(
    fresh_options, monkeypatch
):
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    monkeypatch.delenv("PACJAX_FAST_COMPILE", raising=False)
    # This jaxlib knows them (jax 0.10; an older one may not, and then they are dropped).
    assert dict(_jit.compile_options("cpu")) == _jit.CPU_COMPILE_OPTIONS
    _jit.compile_options.cache_clear()
    monkeypatch.setenv("PACJAX_FAST_COMPILE", "1")
    fast = _jit.CPU_COMPILE_OPTIONS | _jit.FAST_COMPILE_OPTIONS
    assert dict(_jit.compile_options("cpu")) == fast
    monkeypatch.delenv("PACJAX_FAST_COMPILE")
    assert dict(_jit.compile_options("cpu", once=True)) == fast  # a program run once
    monkeypatch.setenv("PACJAX_FAST_COMPILE", "1")
    _jit.compile_options.cache_clear()
    monkeypatch.setenv("XLA_FLAGS", "--xla_backend_optimization_level=2")
    assert dict(_jit.compile_options("cpu")) == _jit.CPU_COMPILE_OPTIONS  # the user's level
    assert dict(_jit.compile_options("cpu", once=True)) == _jit.CPU_COMPILE_OPTIONS
    monkeypatch.delenv("PACJAX_FAST_COMPILE")
    assert _jit.compile_options("gpu") == ()
    _jit.compile_options.cache_clear()
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_use_fusion_emitters=true")
    assert _jit.compile_options("cpu") == ()
    _jit.compile_options.cache_clear()
    monkeypatch.delenv("XLA_FLAGS")
    monkeypatch.setattr(_jit, "CPU_COMPILE_OPTIONS", {"xla_cpu_no_such_option": True})
    assert _jit.compile_options("cpu") == ()


def test_options_only_on_top_level_calls_and_the_same_result(fresh_options, monkeypatch):
    # JAX rejects compile options on a jit nested in another trace: such calls compile
    # without them, as part of the caller's program.
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    monkeypatch.delenv("PACJAX_FAST_COMPILE", raising=False)
    seen = []
    filter_jit = eqx.filter_jit

    def spy(fn, **kwargs):
        seen.append(kwargs.get("compiler_options"))
        return filter_jit(fn, **kwargs)

    monkeypatch.setattr(_jit.eqx, "filter_jit", spy)
    f = _jit.jit(lambda x: jnp.sin(x) * x)
    assert seen == [None]  # the plain version
    x = jnp.linspace(0.1, 1.0, 5)
    top = f(x)
    f(x)
    monkeypatch.undo()
    assert seen == [None, _jit.CPU_COMPILE_OPTIONS]  # made at the first top-level call
    seen.clear()
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    monkeypatch.delenv("PACJAX_FAST_COMPILE", raising=False)
    monkeypatch.setattr(_jit.eqx, "filter_jit", spy)
    once = _jit.jit(once=True)(lambda x: jnp.sin(x) * x)
    np.testing.assert_allclose(once(x), top, rtol=1e-15)
    monkeypatch.undo()
    assert seen == [None, _jit.CPU_COMPILE_OPTIONS | _jit.FAST_COMPILE_OPTIONS]
    np.testing.assert_allclose(jax.jit(f)(x), top, rtol=1e-15)
    np.testing.assert_allclose(jax.vmap(f)(x), top, rtol=1e-15)
    np.testing.assert_allclose(jax.grad(lambda x: f(x).sum())(x), jnp.sin(x) + x * jnp.cos(x))


def test_solve_with_the_options_is_the_solve_without_them():
    seg = pj.Segment(0.15, 0.05, 2000.0, linear_density=0.3)
    tendons = [pj.Tendon(0, a, 0.02, gain=5e3) for a in (0.0, 2 * np.pi / 3, 4 * np.pi / 3)]
    scene = pj.Scene(
        pj.Robot([seg, seg]), pj.PAC(), tendons=tendons, loads=(pj.Gravity(), pj.PointMass(0.1, 1))
    )
    u = np.array([0.006, 0.0, 0.002])
    top = pj.solve_equilibrium(scene, u)  # compiled with the options
    nested = jax.jit(lambda: pj.solve_equilibrium(scene, u))()  # without them
    assert top.converged and nested.converged
    assert int(top.steps) == int(nested.steps)
    np.testing.assert_allclose(top.q, nested.q, rtol=0, atol=1e-12)
