"""The stiffness modes of a linearisation: the eigen-decomposition of the scaled Hessian, the
step that leaves a saddle along its unstable modes, and the saddle-free continuation step of a
conservative scene (:mod:`pacjax._statics.ptc`)."""

import jax.numpy as jnp
from jaxtyping import Array, Float

from .._config import MATMUL_PRECISION
from . import linalg as _linalg


def max_abs(x):
    return jnp.max(jnp.abs(x))


def stiffness_modes(jac, weights, size, tol):
    """Eigen-decomposition of ``K = diag(w) J diag(1/w)`` symmetrised, and an escape step.

    With ``w = sqrt(d) sigma`` the matrix ``K`` is ``D^-1/2 (dF/dq) D^-1/2``: the stiffness
    relative to the elastic stiffness, whose eigenvalue signs are those of the Hessian. The
    escape step (in ``y``) follows every direction of negative curvature at once, so a saddle
    with several unstable modes (one per segment of a robot) is left in one go.
    """
    k = (weights[:, None] * jac) / weights[None, :]
    eigvals, eigvecs = _linalg.eigh(0.5 * (k + k.T))
    unstable = (eigvals < -tol).at[0].set(True)
    dy = (jnp.matmul(eigvecs, jnp.where(unstable, 1.0, 0.0), precision=MATMUL_PRECISION)) / weights
    dy = size * dy / jnp.maximum(max_abs(dy), jnp.finfo(dy.dtype).tiny)
    return eigvals, eigvecs, dy


def saddle_free_step(eigvals, eigvecs, weights, residual, dt) -> Float[Array, " n"]:
    """The continuation step of a conservative scene, from the stiffness modes (``eigvals``,
    ``eigvecs``: :func:`stiffness_modes`) of the linearisation with residual ``residual``.

    ``K`` is the scaled Hessian. Continuation step with ``|lambda|`` ("saddle-free" Newton): full
    Newton along stable modes, descent along the others; ``1 / dt`` shifts every mode.
    """
    rz = jnp.matmul(eigvecs.T, weights * residual, precision=MATMUL_PRECISION)
    gain = 1.0 / (jnp.abs(eigvals) + 1.0 / dt)
    return -(jnp.matmul(eigvecs, gain * rz, precision=MATMUL_PRECISION)) / weights
