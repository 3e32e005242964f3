"""Kinematics: frames along the backbone for any strain model.

One code path for every model. Within a segment the frame obeys ``R'(s) = R(s) [u(s)]x`` and the
backbone ``t'(s) = (L + dL) R(s) e_z``. The rotation is integrated with the fourth-order Magnus
method (two Gauss points per sub-step), which is exact in one step whenever the strain keeps a
fixed axis and is at most cubic in ``s`` (PCC, PAC, planar polynomials up to order 3); the
position is a Gauss-Legendre quadrature of ``R(v) e_z`` over ``[0, s]``. No closed form with a
``1/c1`` singularity, no clamp: everything is smooth through the straight configuration.

Segments are chained by a scan over their end frames, and any set of points ``(segment, s)`` is
evaluated in one ``vmap`` over a padded per-segment grid.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._quadrature import gauss_legendre
from ._rotation import exp_so3, matmul3, matvec3
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
        rot = matmul3(rot, exp_so3(omega))
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
    w = jnp.asarray(weights, q.dtype)
    position = (length + model.elongation(q)) * s * jnp.sum(w[:, None] * tangents, axis=0)
    return rots[-1], position


def grid_frames(
    model: StrainModel,
    q: Float[Array, "n d"],
    lengths: Float[Array, " n"],
    base_rotation: Float[Array, "3 3"],
    base_position: Float[Array, "3"],
    s_grid: Float[Array, "n p"],
    config: KinematicsConfig,
) -> tuple[Float[Array, "n p 3 3"], Float[Array, "n p 3"]]:
    """World rotations and positions (m) of the frames at ``s_grid[i, k]`` on segment ``i``.

    Every segment evaluates the same number of points (a padded grid), so the whole robot is a
    ``vmap`` over segments and points with no gathers: gathers turn into scatters under reverse
    mode, which XLA:CPU runs serially and which do not batch. The segment end frames are computed
    in the same batch, then chained by a scan over segments.
    """
    n = q.shape[0]
    s_all = jnp.concatenate([s_grid.astype(q.dtype), jnp.ones((n, 1), q.dtype)], axis=1)

    def segment(qi, li, si):
        return jax.vmap(lambda sk: local_frame(model, qi, li, sk, config))(si)

    rot, pos = jax.vmap(segment)(q, lengths, s_all)

    def chain(carry, end):
        r, p = carry
        d_rot, d_pos = end
        return (matmul3(r, d_rot), p + matvec3(r, d_pos)), (r, p)

    start = (base_rotation.astype(q.dtype), base_position.astype(q.dtype))
    _, (base_rots, base_pos) = jax.lax.scan(chain, start, (rot[:, -1], pos[:, -1]))
    world_rot = matmul3(base_rots[:, None], rot[:, :-1])
    world_pos = base_pos[:, None, :] + matvec3(base_rots[:, None], pos[:, :-1])
    return world_rot, world_pos


class PointLayout:
    """Static placement of a list of points ``(segment, s)`` on a padded per-segment grid.

    Built in Python from the segment indices only (the ``s`` values may be traced). Selecting
    the points back from the grid is a product with a constant one-hot matrix.
    """

    def __init__(self, n_segments: int, segments):
        counts = [0] * n_segments
        flat = []
        for k in segments:
            k = int(k)
            flat.append(counts[k])
            counts[k] += 1
        self.n_segments = n_segments
        self.width = max(max(counts), 1)
        self.segments = np.asarray([int(k) for k in segments], np.int64)
        self.flat_index = self.segments * self.width + np.asarray(flat, np.int64)
        selector = np.zeros((len(flat), n_segments * self.width))
        selector[np.arange(len(flat)), self.flat_index] = 1.0
        self.selector = selector

    def grid(self, s: Float[Array, " p"], dtype) -> Float[Array, "n w"]:
        """The padded ``(segments, width)`` grid of ``s`` values (padding at ``s = 1``)."""
        flat = jnp.ones(self.n_segments * self.width, dtype)
        flat = flat.at[self.flat_index].set(jnp.asarray(s, dtype))
        return flat.reshape(self.n_segments, self.width)

    def select(self, grid_values: Array) -> Array:
        """Values at the listed points from values on the grid."""
        rest = grid_values.shape[2:]
        flat = grid_values.reshape(self.n_segments * self.width, -1)
        picked = jnp.asarray(self.selector, flat.dtype) @ flat
        return picked.reshape((self.selector.shape[0],) + rest)
