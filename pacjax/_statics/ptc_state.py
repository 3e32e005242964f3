"""The state of :class:`pacjax._statics.ptc.PseudoTransientContinuation` between its steps,
and the result code it ends with."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .._results import MAX_STEPS_REACHED, SUCCESSFUL


class PTCState(eqx.Module):
    """The last accepted point's linearisation (scaled residual, merit, Jacobian, weights), its
    stiffness modes, the pseudo-time step and the escape bookkeeping."""

    residual: Float[Array, " n"]
    merit: Float[Array, ""]
    jacobian: Float[Array, "n n"]
    weights: Float[Array, " n"]
    dt: Float[Array, ""]
    step: Int[Array, ""]
    escapes: Int[Array, ""]
    # Set by an escape, cleared once the stiffness is no longer indefinite: until then a small
    # residual is not convergence (see ``terminate``).
    escaping: Bool[Array, ""]
    # Steps left after an escape (0 once the stiffness is no longer indefinite) in which a
    # non-conservative solve takes no plain Newton step (see ``_LEAVING_STEPS``).
    leaving: Int[Array, ""]
    eig: Float[Array, ""]
    eigvals: Float[Array, " n"]
    eigvecs: Float[Array, "n n"]
    escape_dy: Float[Array, " n"]
    # Non-conservative generalised force at ``y`` (scaled), frozen for the merit of the next
    # step (``frozen_work``).
    drive: Float[Array, " n"]
    code: Int[Array, ""]
    # With ``ahead``: the next step tried from ``y`` along this state's linearisation, its end
    # point, residual and merit, and the step's size. Where that residual is converged the
    # solve ends there without a linearisation of its own (``finish``).
    ahead_y: Float[Array, " n"]
    ahead_residual: Float[Array, " n"]
    ahead_merit: Float[Array, ""]
    ahead_size: Float[Array, ""]
    # Whether that point is the plain sum ``y + delta`` (see ``_plain_near``).
    ahead_plain: Bool[Array, ""]


def final_code(state: PTCState, converged) -> Int[Array, ""]:
    """The :class:`pacjax.RESULTS` code after a run (see :func:`pacjax._results.from_code`)."""
    return jnp.where(
        converged,
        SUCCESSFUL,
        jnp.where(state.code == SUCCESSFUL, MAX_STEPS_REACHED, state.code),
    )
