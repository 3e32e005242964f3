"""The derivative of an equilibrium in the scene and the commands, by the implicit function
theorem with the solver's own last linearisation.

At an equilibrium ``F(q*, u, p) = 0``, so ``dq* = -(dF/dq)^-1 (dF/du du + dF/dp dp)``. The
continuation already holds ``dF/dq`` at its last iterate, scaled as it solves
(``r(y) = row * F(sigma * y)``), so a derivative costs one directional derivative of the
residual in the inputs and one dense solve. Differentiating the solver instead (optimistix's
implicit adjoint) linearises the residual in ``q`` once more and, in reverse mode, transposes
that: a larger program, slower to compile, for the same derivative (``benchmarks/RESULTS.md``,
"Equilibrium derivatives").
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.custom_derivatives import SymbolicZero


def implicit_equilibrium(scene, controls, q, jacobian, sigma, row):
    """``q`` (an equilibrium of ``scene`` under ``controls``, found with no derivative flowing)
    with its derivative in the scene's and the commands' arrays from the implicit function
    theorem; ``jacobian`` is ``d(row * F(sigma * y)) / dy`` there. Where it is singular the
    derivative is not finite (the value is ``q`` whatever it is)."""
    dynamic, static = eqx.partition((scene, controls), eqx.is_array)
    return _implicit(static, q, jacobian, sigma, row, dynamic)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _implicit(static, q, jacobian, sigma, row, dynamic):
    return q


def _implicit_jvp(static, primals, tangents):
    q, jacobian, sigma, row, dynamic = primals
    d_q, *_, d_dynamic = tangents
    # Only the inputs that carry a derivative enter the residual's directional derivative: a
    # gradient by the commands must not trace the residual's derivative in every scene array.
    moving = jax.tree.map(lambda t: not isinstance(t, SymbolicZero), d_dynamic)
    leaves, fixed = eqx.partition(dynamic, moving)
    d_leaves = eqx.filter(d_dynamic, moving)
    d_q = jnp.zeros_like(q) if isinstance(d_q, SymbolicZero) else d_q
    if not jax.tree.leaves(d_leaves):
        return q, d_q

    def residual(arrays):
        scene, controls = eqx.combine(arrays, fixed, static)
        return scene.residual(q, controls)

    _, d_residual = jax.jvp(residual, (leaves,), (d_leaves,))
    step = jnp.linalg.solve(jacobian, row * d_residual)
    return q, d_q - sigma * step


_implicit.defjvp(_implicit_jvp, symbolic_zeros=True)
