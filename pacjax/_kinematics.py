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


def local_rotation(
    model: StrainModel, q: Float[Array, " d"], s: Float[Array, ""], substeps: int
) -> Float[Array, "3 3"]:
    """Rotation of the frame at ``s`` relative to the segment's base frame."""
    base = model.base_rotation(q)
    rot = jnp.eye(3, dtype=q.dtype) if base is None else base
    h = s / substeps
    for k in range(substeps):
        a = k * h
        u1 = model.strain(q, a + _C1 * h)
        u2 = model.strain(q, a + _C2 * h)
        omega = 0.5 * h * (u1 + u2) + _MAGNUS_COMMUTATOR * h * h * jnp.cross(u1, u2)
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
    nodes = jnp.asarray(nodes, q.dtype)
    weights = jnp.asarray(weights, q.dtype)
    substeps = config.rotation_substeps

    def tangent(v):
        return local_rotation(model, q, v, substeps)[:, 2]

    tangents = jax.vmap(tangent)(s * nodes)
    position = (length + model.elongation(q)) * s * (weights @ tangents)
    return local_rotation(model, q, s, substeps), position


def base_frames(
    model: StrainModel,
    q: Float[Array, "n d"],
    lengths: Float[Array, " n"],
    base_rotation: Float[Array, "3 3"],
    base_position: Float[Array, "3"],
    config: KinematicsConfig,
) -> tuple[Float[Array, "n 3 3"], Float[Array, "n 3"]]:
    """World frame at the base (``s = 0``) of every segment."""
    one = jnp.ones((), q.dtype)
    end_rot, end_pos = jax.vmap(lambda qi, li: local_frame(model, qi, li, one, config))(q, lengths)

    def chain(carry, end):
        rot, pos = carry
        d_rot, d_pos = end
        return (rot @ d_rot, pos + rot @ d_pos), (rot, pos)

    start = (base_rotation.astype(q.dtype), base_position.astype(q.dtype))
    _, (rots, positions) = jax.lax.scan(chain, start, (end_rot, end_pos))
    return rots, positions


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
    """World rotations and positions (m) of the frames at points ``(segment[k], s[k])``."""
    rots, positions = base_frames(model, q, lengths, base_rotation, base_position, config)
    s = jnp.asarray(s, q.dtype)

    def one(k, sk):
        rot, pos = local_frame(model, q[k], lengths[k], sk, config)
        return rots[k] @ rot, positions[k] + rots[k] @ pos

    return jax.vmap(one)(segment, s)
