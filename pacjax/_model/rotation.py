"""Rotations: the hat map, the exponential map of SO(3), and elementary rotations.

The exponential map is written so that its value and its first and second derivatives are exact
at zero rotation (the straight robot): the kernels ``sin(t)/t`` and ``(1 - cos t)/t^2`` switch
to their series in ``t^2`` below a small threshold, behind a double ``where`` so that the unused
branch never produces a NaN gradient.
"""

import jax.numpy as jnp
from jaxtyping import Array, Float

# Below this squared angle the kernels use their series (4 terms: truncation error < 1e-18).
_SERIES_THRESHOLD = 1e-3


def hat(v: Float[Array, "3"]) -> Float[Array, "3 3"]:
    """Skew-symmetric matrix ``[v]x`` with ``[v]x w = v x w``."""
    x, y, z = v[0], v[1], v[2]
    zero = jnp.zeros_like(x)
    return jnp.stack(
        [
            jnp.stack([zero, -z, y]),
            jnp.stack([z, zero, -x]),
            jnp.stack([-y, x, zero]),
        ]
    )


def _exp_kernels(theta_sq: Float[Array, ""]) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """``sin(t)/t`` and ``(1 - cos t)/t^2`` as functions of ``t^2``, smooth at 0."""
    small = theta_sq < _SERIES_THRESHOLD
    safe_sq = jnp.where(small, jnp.ones_like(theta_sq), theta_sq)
    theta = jnp.sqrt(safe_sq)
    half = 0.5 * theta
    half_sin = jnp.sin(half)
    # sin t = 2 sin(t/2) cos(t/2): one angle, whose sine and cosine XLA computes together.
    sinc = 2.0 * half_sin * jnp.cos(half) / theta
    # 1 - cos t = 2 sin^2(t/2) avoids the cancellation that ruins float32 near 0.
    cosc = 2.0 * half_sin * half_sin / safe_sq
    t2 = theta_sq
    sinc_series = 1.0 - t2 / 6.0 * (1.0 - t2 / 20.0 * (1.0 - t2 / 42.0))
    cosc_series = 0.5 - t2 / 24.0 * (1.0 - t2 / 30.0 * (1.0 - t2 / 56.0))
    return jnp.where(small, sinc_series, sinc), jnp.where(small, cosc_series, cosc)


def cross3(a, b):
    # Written out: jnp.cross lowers to slices and concatenations that XLA:CPU fuses poorly.
    return (
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    )


def exp_so3(omega: Float[Array, "3"]) -> Float[Array, "3 3"]:
    """Rotation matrix ``exp([omega]x)`` (Rodrigues' formula).

    As ``(1 - b |w|^2) I + b w w^T + a [w]x`` (``[w]x^2 = w w^T - |w|^2 I``): the identity and
    the outer product broadcast, rather than nine entries stacked one by one into the matrix,
    whose derivatives are sliced apart again.
    """
    sq = omega[0] * omega[0] + omega[1] * omega[1] + omega[2] * omega[2]
    a, b = _exp_kernels(sq)
    eye = jnp.eye(3, dtype=omega.dtype)
    return (1.0 - b * sq) * eye + b * omega[:, None] * omega[None, :] + a * hat(omega)


def rot_z(angle: Float[Array, ""]) -> Float[Array, "3 3"]:
    """Rotation by ``angle`` (rad) about the z axis."""
    c, s = jnp.cos(angle), jnp.sin(angle)
    zero, one = jnp.zeros_like(c), jnp.ones_like(c)
    return jnp.stack(
        [jnp.stack([c, -s, zero]), jnp.stack([s, c, zero]), jnp.stack([zero, zero, one])]
    )


def rotate_ez(omega: Float[Array, "*p 3"]) -> Float[Array, "*p 3"]:
    """``exp([omega]x) e_z`` for a stack of rotation vectors, without forming the matrices.

    Written out for ``e_z``: a general ``exp([omega]x) v`` multiplies by the known zeros and ones
    of ``v``, and its first and second derivatives keep those products (XLA does not fold a
    float times zero), while the position nodes' second derivatives are a large part of a
    ``PolynomialCurvature`` linearisation.
    """
    x, y, z = omega[..., 0], omega[..., 1], omega[..., 2]
    a, b = _exp_kernels(x * x + y * y + z * z)
    # omega x e_z = (y, -x, 0); omega x (omega x e_z) = (x z, y z, -(x^2 + y^2)).
    return jnp.stack([a * y + b * x * z, b * y * z - a * x, 1.0 - b * (x * x + y * y)], axis=-1)


def matmul3(a: Float[Array, "*b 3 3"], b: Float[Array, "*b 3 3"]) -> Float[Array, "*b 3 3"]:
    """``a @ b`` for stacks of 3x3 matrices, as a multiply-and-sum.

    On XLA:CPU a dot is a kernel call of its own, and a 3x3 product costs little beside that
    call; elementwise, the products fuse with their neighbours into fewer kernels. The sum over
    three terms rounds as the dot's does.
    """
    return jnp.sum(a[..., :, :, None] * b[..., None, :, :], axis=-2)


def matvec3(a: Float[Array, "*b 3 3"], v: Float[Array, "*b 3"]) -> Float[Array, "*b 3"]:
    """``a @ v`` for stacks of 3x3 matrices and vectors (multiply-and-sum, as :func:`matmul3`)."""
    return jnp.sum(a * v[..., None, :], axis=-1)
