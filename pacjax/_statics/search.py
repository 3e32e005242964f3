"""The search along a continuation step: the longest acceptable length, on the merit alone.

From the full step (``alpha = 1``), ever shorter trial lengths until the merit at the trial point
does not rise above the start's beyond its rounding, down to :data:`MIN_ALPHA`. Each shorter
length minimises the quadratic through the merit and its slope at 0 and the merit at the last
trial (Nocedal and Wright, section 3.5). No Jacobian is evaluated along the way: the residual
comes with the linearisation at the accepted point
(:class:`pacjax._statics.ptc.PseudoTransientContinuation`).
"""

from collections.abc import Callable

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from .._config import MATMUL_PRECISION

#: The shortest trial length; a search that finds none acceptable stops there.
MIN_ALPHA = 1.0 / 256

# Relative rounding, in machine epsilons, within which a merit counts as not risen.
_ROUNDING = 64


def descends(merit: Float[Array, ""], merit0: Float[Array, ""]) -> Bool[Array, ""]:
    """Whether ``merit`` is finite and not above ``merit0`` beyond the rounding of the two."""
    eps = jnp.finfo(jnp.result_type(merit, merit0)).eps
    slack = _ROUNDING * eps * (jnp.abs(merit0) + jnp.abs(merit))
    return jnp.isfinite(merit) & (merit <= merit0 + slack)


def energy_slope(y, weights, residual, merit, delta):
    """The slope along ``delta`` at ``y`` of an energy merit whose gradient in the scaled
    coordinates is ``weights^2 residual``, and ``rounding``: whether the full step is taken
    unchecked.

    Near a solution the merit's change is below its rounding, and a rise there says nothing: a
    full step whose predicted decrease is within the rounding of the merit's terms (bounded by
    the elastic energy ``(weights y)^2`` beside the merit) is taken.
    """
    eps = jnp.finfo(y.dtype).eps
    slope = jnp.dot(weights**2 * residual, delta, precision=MATMUL_PRECISION)
    scale = jnp.abs(merit) + jnp.sum((weights * y) ** 2)
    rounding = (slope <= 0) & (-slope <= _ROUNDING * eps * scale)
    return slope, rounding


def shorter(alpha, merit, merit0, slope):
    """The next, shorter trial length after ``alpha``, whose merit ``merit`` did not descend.

    The minimiser of the quadratic through ``merit0``, the ``slope`` at 0 and ``merit`` at
    ``alpha``, within ``[alpha / 10, alpha / 2]``; half the step where that quadratic has no
    minimum (or the slope is unknown, ``nan``).
    """
    # Under vmap the search runs as long as its slowest row, and the rows that overshoot do so
    # by 8-16x (the paper's robot, third step, where dt has grown to 20 against a soft mode):
    # halving took them 3-4 trials, the quadratic mostly 1.
    curv = merit - merit0 - slope * alpha
    fit = (curv > 0) & (slope < 0)
    guess = -slope * alpha**2 / (2.0 * jnp.where(fit, curv, 1.0))
    guess = jnp.where(fit & jnp.isfinite(guess), guess, 0.5 * alpha)
    return jnp.clip(guess, 0.1 * alpha, 0.5 * alpha)


def backtrack(
    merit_at: Callable[[Array], Array],
    merit0: Float[Array, ""],
    merit_full: Float[Array, ""],
    ok_full: Bool[Array, ""],
    slope: Float[Array, ""],
    take_any: Bool[Array, ""],
) -> tuple[Float[Array, ""], Bool[Array, ""]]:
    """The accepted length ``alpha`` and ``ok``: whether it is acceptable.

    Args:
        merit_at: the merit at the trial point of a length.
        merit0: the merit at the start.
        merit_full, ok_full: the full step's merit and whether that step is acceptable.
        slope: the merit's slope along the step at the start (``nan``: unknown; the lengths
            then halve).
        take_any: every trial length is acceptable (the first step, an escape from a saddle).
    """

    def cond(carry):
        alpha, _, ok = carry
        return ~ok & (alpha > MIN_ALPHA)

    def body(carry):
        alpha, merit, _ = carry
        alpha = shorter(alpha, merit, merit0, slope)
        merit = merit_at(alpha)
        return alpha, merit, descends(merit, merit0) | take_any

    alpha, _, ok = jax.lax.while_loop(
        cond, body, (jnp.asarray(1.0, merit0.dtype), merit_full, ok_full)
    )
    return alpha, ok
