"""The implicit solvers' chord root finder (:mod:`pacjax._chord`): diffrax's ``VeryChord`` with a
forward-mode Jacobian. Same Jacobian and the same integration as diffrax's own."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from pacjax._chord import DenseChord, kvaerno5


def _relation(y, args):
    """A nonlinear map on a pytree (two leaves of different sizes), with a root near 0."""
    a, b = y
    scale = args
    out_a = a + 0.1 * jnp.sin(b[:2]) * scale - jnp.array([0.3, -0.2])
    out_b = b + 0.05 * jnp.concatenate([a * a, a[:1] * b[2:]]) - jnp.array([0.1, 0.2, -0.1])
    return (out_a, out_b), None


def _init(finder, y, scale):
    struct = jax.eval_shape(lambda: _relation(y, scale)[0])
    return finder.init(_relation, y, scale, {}, struct, None, frozenset())


def test_jacobian_is_verychords():
    y = (jnp.array([0.4, -0.7]), jnp.array([0.3, 0.9, -1.2]))
    dense = _init(DenseChord(rtol=1e-10, atol=1e-12), y, 2.0)
    reference = _init(diffrax.VeryChord(rtol=1e-10, atol=1e-12), y, 2.0)
    expected = np.asarray(reference.linear_state[0].as_matrix())
    got = np.asarray(dense.linear_state[0].as_matrix())
    assert expected.shape == (5, 5)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-15)
    # The rest of the state is VeryChord's.
    for field in ("diffsize", "diffsize_prev", "step"):
        assert float(getattr(dense, field)) == float(getattr(reference, field))


def test_kvaerno5_integrates_a_stiff_problem_as_diffraxs():
    """Van der Pol at mu = 1000 (stiff): the same steps and the same state as diffrax's
    default Kvaerno5."""

    def field(t, y, args):
        x, v = y
        return v, args * (1 - x * x) * v - x

    def solve(solver):
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(field),
            solver,
            0.0,
            2.0,
            None,
            (jnp.asarray(2.0), jnp.asarray(0.0)),
            args=1000.0,
            stepsize_controller=diffrax.PIDController(rtol=1e-8, atol=1e-10),
            max_steps=10_000,
        )
        return np.asarray([sol.ys[0][-1], sol.ys[1][-1]]), int(sol.stats["num_steps"])

    state, steps = solve(kvaerno5())
    reference, reference_steps = solve(diffrax.Kvaerno5())
    assert steps == reference_steps
    np.testing.assert_allclose(state, reference, rtol=1e-10, atol=1e-12)
