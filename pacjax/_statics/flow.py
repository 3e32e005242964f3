"""The continuation step of a non-conservative scene: a short stretch of the shifted flow, or
Newton's step where it halves the residual near a solution.

Non-conservative loads (follower forces, dead moments in 3D) make the Jacobian ``J`` not
symmetric. Far from a solution it is shifted by enough to dominate the negative curvature of its
symmetric part, ``(J + I / dt) dy = -r`` with ``dt`` capped by that curvature: a short stretch of
the flow. The cap makes the steps creep near a solution whose symmetric part is indefinite (a
dead moment bending a twistable rod past ~2 rad); there (scaled residual below
:data:`NEWTON_NEAR`, forces 1 % of the elastic scale) the plain Newton step ``J dy = -r`` is
tried first and taken when it halves the residual (one more residual evaluation). Far away it is
not: from a straight PCC/PAC segment it jumps to the spurious polar equilibrium (phi along the
moment, no bending).
"""

from collections.abc import Callable

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from . import linalg as _linalg
from .modes import max_abs

#: Scaled residual below which a non-conservative solve tries plain Newton steps first.
NEWTON_NEAR = 1e-2


def shifted_flow_step(
    residual_at: Callable[[Array], Array],
    moved: Callable[[Array], Array],
    jacobian: Float[Array, "n n"],
    residual: Float[Array, " n"],
    dt: Float[Array, ""],
    eig: Float[Array, ""],
    newton_allowed: Bool[Array, ""],
    near_needs_negative: bool,
) -> tuple[Float[Array, " n"], Bool[Array, ""]]:
    """``(step, took_newton)`` from the linearisation ``(jacobian, residual)``.

    Args:
        residual_at: the residual at a point.
        moved: the point after a step from the current one.
        dt: the pseudo-time step; ``eig`` the lowest eigenvalue of the scaled symmetric
            stiffness, which caps it where negative.
        newton_allowed: whether a Newton step may be taken at all (not on a first step, an
            escape, or while leaving a saddle).
        near_needs_negative: Newton's step is tried near a solution only where the stiffness
            is indefinite (when the merit is not the frozen work, whose search handles the
            rest).
    """
    # Both systems go to LAPACK as one batched factorisation. Two independent solves are two
    # custom calls that XLA:CPU may run at once, and jaxlib 0.10's batched LAPACK kernels then
    # each wait on sub-tasks queued to the same intra-op thread pool: with as many such calls
    # as pool threads (2 on a 2-core machine), every thread waits and the program hangs (seen
    # in gdb: both in LuDecompositionKernel -> ParallelBatchMap -> BlockingCounter::Wait).
    # pacjax._statics.linalg keeps every call below the size that takes that path; one call is
    # also cheaper than two.
    n = residual.shape[0]
    eye = jnp.eye(n, dtype=residual.dtype)
    dt_safe = jnp.where(eig < 0, jnp.minimum(dt, 0.5 / -eig), dt)
    matrices = jnp.stack([jacobian + eye / dt_safe, jacobian])
    rhs = jnp.broadcast_to(-residual[:, None], (2, n, 1))
    flow, full = _linalg.solve(matrices, rhs)[..., 0]

    near = max_abs(residual) <= NEWTON_NEAR
    if near_needs_negative:
        near = near & (eig < 0)
    # (Under vmap a cond runs both branches: the trial is evaluated for every row.)
    r_newton = residual_at(moved(full))
    took_newton = near & jnp.all(jnp.isfinite(full)) & jnp.all(jnp.isfinite(r_newton))
    took_newton = took_newton & (max_abs(r_newton) <= 0.5 * max_abs(residual))
    took_newton = took_newton & newton_allowed
    return jnp.where(took_newton, full, flow), took_newton
