"""Kinematics: frames along the backbone for any strain model.

One code path for every model. Within a segment the frame obeys ``R'(s) = R(s) [u(s)]x`` and the
backbone ``t'(s) = (L + dL) R(s) e_z``. The rotation is integrated with the fourth-order Magnus
method (two Gauss points per sub-step), which is exact in one step whenever the strain keeps a
fixed axis and is at most cubic in ``s`` (PCC, PAC, planar polynomials up to order 3); the
position is a Gauss-Legendre quadrature of ``R(v) e_z`` over ``[0, s]``. No closed form with a
``1/c1`` singularity, no clamp: everything is smooth through the straight configuration.

Segments are chained by a scan over their end frames, and any set of points ``(segment, s)`` is
evaluated in one ``vmap``.
"""

import math

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ._quadrature import gauss_legendre
from ._rotation import exp_so3
from ._strain import StrainModel

_C1 = 0.5 - math.sqrt(3.0) / 6.0
_C2 = 0.5 + math.sqrt(3.0) / 6.0
_MAGNUS_COMMUTATOR = math.sqrt(3.0) / 12.0


class KinematicsConfig:
    """Static settings of the kinematics (part of a scene's structure)."""

    __slots__ = ("quadrature_points", "rotation_substeps")

    def __init__(self, quadrature_points: int, rotation_substeps: int):
        self.quadrature_points = quadrature_points
        self.rotation_substeps = rotation_substeps


def _magnus_steps(model: StrainModel, q, s, substeps: int) -> list:
    """Fourth-order Magnus rotation vectors of the sub-steps of ``[0, s]``."""
    h = s / substeps
    steps = []
    for k in range(substeps):
        a = k * h
        u1 = model.strain(q, a + _C1 * h)
        u2 = model.strain(q, a + _C2 * h)
        steps.append(0.5 * h * (u1 + u2) + _MAGNUS_COMMUTATOR * h * h * jnp.cross(u1, u2))
    return steps


def local_rotation(
    model: StrainModel, q: Float[Array, " d"], s: Float[Array, ""], substeps: int
) -> Float[Array, "3 3"]:
    """Rotation of the frame at ``s`` relative to the segment's base frame."""
    base = model.base_rotation(q)
    rot = jnp.eye(3, dtype=q.dtype) if base is None else base
    for omega in _magnus_steps(model, q, s, substeps):
        rot = rot @ exp_so3(omega)
    return rot


def local_frame(
    model: StrainModel,
    q: Float[Array, " d"],
    length: Float[Array, ""],
    s: Float[Array, ""],
    config: KinematicsConfig,
) -> tuple[Float[Array, "3 3"], Float[Array, "3"]]:
    """Rotation and position (m) of the frame at ``s`` in the segment's base frame."""
    nodes, weights = gauss_legendre(config.quadrature_points)
    # The frame at s and at the quadrature nodes of [0, s] in one vmapped evaluation, so the
    # rotation is traced once (compile time scales with the size of the traced graph).
    where = jnp.concatenate([s * jnp.asarray(nodes, q.dtype), s[None]])
    rots = jax.vmap(lambda v: local_rotation(model, q, v, config.rotation_substeps))(where)
    tangents = rots[:-1, :, 2]
    position = (length + model.elongation(q)) * s * (jnp.asarray(weights, q.dtype) @ tangents)
    return rots[-1], position


def frames_at(
    model: StrainModel,
    q: Float[Array, "n d"],
    lengths: Float[Array, " n"],
    base_rotation: Float[Array, "3 3"],
    base_position: Float[Array, "3"],
    segment: Int[Array, " p"],
    s: Float[Array, " p"],
    config: KinematicsConfig,
) -> tuple[Float[Array, "p 3 3"], Float[Array, "p 3"]]:
    """World rotations and positions (m) of the frames at points ``(segment[k], s[k])``.

    The segment end frames are evaluated in the same batch as the requested points, then
    chained by a scan over segments.
    """
    n = q.shape[0]
    all_segments = jnp.concatenate([jnp.arange(n, dtype=segment.dtype), segment])
    all_s = jnp.concatenate([jnp.ones(n, q.dtype), jnp.asarray(s, q.dtype)])
    rot, pos = jax.vmap(lambda k, sk: local_frame(model, q[k], lengths[k], sk, config))(
        all_segments, all_s
    )

    def chain(carry, end):
        r, p = carry
        d_rot, d_pos = end
        return (r @ d_rot, p + r @ d_pos), (r, p)

    start = (base_rotation.astype(q.dtype), base_position.astype(q.dtype))
    _, (base_rots, base_pos) = jax.lax.scan(chain, start, (rot[:n], pos[:n]))
    r_base, p_base = base_rots[segment], base_pos[segment]
    return r_base @ rot[n:], p_base + jnp.einsum("pij,pj->pi", r_base, pos[n:])
