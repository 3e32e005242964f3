"""Sine and cosine of an angle together, as arithmetic that XLA fuses and vectorises.

XLA:CPU evaluates a float64 ``sin`` or ``cos`` as a call into the C library, one element at a
time, inside otherwise vectorised loops. The kinematics of PCC and PAC take the sine and cosine
of every bending and plane angle at every knot, and their derivatives take them again, so those
calls were the largest single cost of a dynamics vector field (profile in
``benchmarks/RESULTS.md``). :func:`sincos` computes the pair in float64 with the
classical reduction and polynomials, which XLA compiles into the surrounding fused loop, and its
derivative reuses the pair instead of computing it again. Other precisions take ``jnp.sin`` and
``jnp.cos``, whose float32 forms XLA already writes as vectorised polynomials.

The polynomials make a program larger and slower to compile. A statics solve runs its program a
few times and gains nothing from them; a simulation runs its vector field thousands of times.
So the strain models use the library's by default, and :func:`pacjax.simulate` turns the fused
ones on for the scenes it integrates (``PlanarCurvature.fused_trig``).

The method (as in fdlibm and Cephes): ``x = j pi/2 + r`` with ``j`` the nearest integer to
``x / (pi/2)`` and ``r`` in ``[-pi/4, pi/4]``, computed with ``pi/2`` split into three parts
(Cody and Waite) so that ``j`` times each of the first two is exact while ``|j| < 2^20``
(``|x|`` below about 1.6e6 rad; beyond, the reduction loses digits gradually, and no bending
angle of a body comes near); then the Taylor polynomials of ``sin r`` (to ``r^17``) and
``cos r`` (to ``r^18``), whose remainders on that interval are below 1e-19, and the quadrant
``j mod 4`` picks and signs them.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

# pi/2 = _HALF_PI[0] + _HALF_PI[1] + _HALF_PI[2]: the first two hold 33 significant bits each, so
# j * part is exact for |j| < 2^20; the third is the rest, rounded to double.
_HALF_PI = (1.5707963267341256, 6.077100506303966e-11, 2.0222662487959506e-21)
# Taylor coefficients of (sin r - r) / r^3 and (cos r - 1) / r^2 as polynomials in z = r^2, as
# the columns of one matrix: both come from one product with the powers of z.
_TAYLOR = np.array(
    [
        [(-1) ** (k + 1) / math.factorial(2 * k + 3), (-1) ** (k + 1) / math.factorial(2 * k + 2)]
        for k in range(9)
    ]
)
_TAYLOR[8, 0] = 0.0  # sin needs the powers z^0 .. z^7 only


def _sincos64(x):
    j = jnp.round(x * (2.0 / math.pi))
    r = ((x - j * _HALF_PI[0]) - j * _HALF_PI[1]) - j * _HALF_PI[2]
    z = r * r
    z2 = z * z
    z4 = z2 * z2
    low = jnp.stack([jnp.ones_like(z), z, z2, z2 * z], axis=-1)
    powers = jnp.concatenate([low, low * z4[..., None], (z4 * z4)[..., None]], axis=-1)
    ps, pc = jnp.moveaxis(jnp.matmul(powers, _TAYLOR.astype(x.dtype), precision="highest"), -1, 0)
    s = r + r * z * ps
    c = 1.0 + z * pc
    # The quadrant j mod 4: odd ones swap sine and cosine, and the bits of j and j + 1 sign them.
    k = j.astype(jnp.int64)
    odd = (k & 1) == 1
    sin = jnp.where(odd, c, s) * jnp.where((k & 2) == 0, 1.0, -1.0)
    cos = jnp.where(odd, s, c) * jnp.where(((k + 1) & 2) == 0, 1.0, -1.0)
    return sin, cos


@jax.custom_jvp
def sincos(x: Float[Array, "*n"]) -> tuple[Float[Array, "*n"], Float[Array, "*n"]]:
    """``(sin x, cos x)``, equal to ``jnp.sin`` and ``jnp.cos`` to rounding (see the module)."""
    x = jnp.asarray(x)
    if x.dtype == jnp.float64:
        return _sincos64(x)
    return jnp.sin(x), jnp.cos(x)


@sincos.defjvp
def _sincos_jvp(primals, tangents):
    (x,), (t,) = primals, tangents
    s, c = sincos(x)
    return (s, c), (c * t, -s * t)


def library_sincos(x: Float[Array, "*n"]) -> tuple[Float[Array, "*n"], Float[Array, "*n"]]:
    """``(jnp.sin x, jnp.cos x)``: :func:`sincos`'s library form, cheaper to compile."""
    return jnp.sin(x), jnp.cos(x)


def sin_cos_versine(theta: Float[Array, "*n"], pair=library_sincos):
    """``(sin t, cos t, 1 - cos t)`` from one ``pair`` (:func:`sincos` or
    :func:`library_sincos`) of ``t / 2``, with ``1 - cos t`` as ``2 sin^2(t / 2)``, which keeps its
    relative precision near ``t = 0`` (straight)."""
    s, c = pair(0.5 * theta)
    return 2.0 * s * c, (c - s) * (c + s), 2.0 * s * s
