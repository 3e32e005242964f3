"""The solver's batched LAPACK calls stay inline on a CPU (``pacjax._statics.linalg``): XLA's
intra-op thread pool is never waited on, so two pool lanes (or devices) cannot hang."""

import jax
import jax.numpy as jnp
import numpy as np

from pacjax._statics import linalg


def _batch_dims(fn, *args) -> set[str]:
    """``num_batch_dims`` of every LU factorisation in ``fn``'s program."""
    text = jax.jit(fn).lower(*args).as_text()
    return {
        line.split('num_batch_dims = "')[1].split('"')[0]
        for line in text.splitlines()
        if "getrf" in line and "num_batch_dims" in line
    }


def _systems(n, count, seed=0):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(count, n, n)) + n * np.eye(n)
    b = rng.normal(size=(count, n, 1))
    return jnp.asarray(a), jnp.asarray(b)


def test_a_problem_of_two_large_systems_is_solved_one_matrix_per_call():
    """Found by the campaign: two 100 x 100 systems in one call went to the thread pool (a
    12-segment cubic robot under a follower force hung with two lanes)."""
    a, b = _systems(100, 2)
    assert _batch_dims(linalg.solve, a, b) == {"0"}  # one system per call, not a batch of two
    np.testing.assert_allclose(linalg.solve(a, b), jnp.linalg.solve(a, b), rtol=1e-12)
    w, v = linalg.eigh(a + jnp.swapaxes(a, -1, -2))
    np.testing.assert_allclose(w, jnp.linalg.eigh(a + jnp.swapaxes(a, -1, -2))[0], rtol=1e-10)


def test_small_systems_stay_one_call():
    a, b = _systems(12, 2)
    assert _batch_dims(linalg.solve, a, b) == {"1"}  # one call of both: inline at this size
    batched = jax.vmap(linalg.solve)(jnp.stack([a, a]), jnp.stack([b, b]))
    np.testing.assert_allclose(batched[1], jnp.linalg.solve(a, b), rtol=1e-12)
