"""Kinematics: frames along the backbone for any strain model.

One code path for every model. Within a segment the frame obeys ``R'(s) = R(s) [u(s)]x`` and the
backbone ``t'(s) = (L + dL) R(s) e_z``. The rotation is integrated with the fourth-order Magnus
method (two Gauss points per sub-step), which is exact in one step whenever the strain keeps a
fixed axis and is at most cubic in ``s`` (PCC, PAC, planar polynomials up to order 3); the
position is a Gauss-Legendre quadrature of ``R(v) e_z`` over ``[0, s]``. No closed form with a
``1/c1`` singularity, no clamp: everything is smooth through the straight configuration.

Two evaluation paths share these rules:

- **Knots** (points whose ``s`` is known at trace time: tendon guide rings, quadrature nodes of
  the distributed weight, markers): every segment is cut at the sorted union of its points and an
  even grid of at least 8 intervals. One Magnus step per interval gives the rotation increments,
  chained by a short scan; the position is the cumulative sum of a 4-point Gauss-Legendre rule
  per interval (error ~1e-9 relative even at 2 pi of bending per segment). Each point costs about
  four exponentials whatever its ``s``, and points shared by several tendons are evaluated once.
  The grid, ``(8, 4)`` here, is the scene's :attr:`~pacjax.Scene.knot_grid`; the dynamics take a
  coarser one at their default tolerances (:data:`pacjax.dynamics.KNOT_GRID`).
- **Traced points** (``s`` only known at run time): ``[0, s]`` is cut in the same number of even
  intervals and integrated by the same rules, from the segment's base.

Segments are chained by a scan over their end frames.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import MATMUL_PRECISION
from .quadrature import gauss_legendre
from .rotation import cross3, exp_so3, matmul3, matvec3, rotate_ez
from .strain import StrainModel

_C1 = 0.5 - math.sqrt(3.0) / 6.0
_C2 = 0.5 + math.sqrt(3.0) / 6.0
_MAGNUS_COMMUTATOR = math.sqrt(3.0) / 12.0


#: The knot path's default grid: at least this many intervals per segment, and Gauss-Legendre
#: position nodes per interval (positions to round-off: see the module's docstring).
DEFAULT_KNOT_GRID = (8, 4)
# Knots closer than this (in s) are merged.
_KNOT_MERGE = 1e-12


class KinematicsConfig:
    """Static settings of the kinematics (part of a scene's structure): Magnus sub-steps per
    segment, and the knot grid ``(intervals, nodes)`` (:data:`DEFAULT_KNOT_GRID` by default)."""

    __slots__ = ("rotation_substeps", "grid")

    def __init__(self, rotation_substeps: int, grid: tuple[int, int] = DEFAULT_KNOT_GRID):
        self.rotation_substeps = rotation_substeps
        self.grid = grid

    @property
    def min_intervals(self) -> int:
        return max(self.grid[0], self.rotation_substeps)

    @property
    def interval_nodes(self) -> int:
        return self.grid[1]


def _magnus_step(model: StrainModel, q, a, h):
    """Fourth-order Magnus rotation vector of the interval ``[a, a + h]``."""
    u1 = model.strain(q, a + _C1 * h)
    u2 = model.strain(q, a + _C2 * h)
    c = cross3(u1, u2)
    return 0.5 * h * (u1 + u2) + _MAGNUS_COMMUTATOR * h * h * jnp.stack(c)


def local_frame(
    model: StrainModel,
    q: Float[Array, " d"],
    length: Float[Array, ""],
    s: Float[Array, ""],
    config: KinematicsConfig,
) -> tuple[Float[Array, "3 3"], Float[Array, "3"]]:
    """Rotation and position (m) of the frame at ``s`` in the segment's base frame.

    ``[0, s]`` is cut in ``config.min_intervals`` even intervals and integrated as the knot path
    integrates a segment (:func:`segment_knot_frames`), so a traced site is as accurate as a
    known one wherever it lies: one Gauss-Legendre rule over ``[0, s]`` is not (on a segment
    curled by 9.5 rad an 8-point rule misplaces a site by 0.14 m).
    """
    knots = s * jnp.linspace(0.0, 1.0, config.min_intervals + 1, dtype=q.dtype)
    rots, positions, _ = segment_knot_frames(
        model, q, length, knots, interval_nodes=config.interval_nodes
    )
    return rots[-1], positions[-1]


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
    base_rots, base_pos = chain_segments(rot[:, -1], pos[:, -1], base_rotation, base_position)
    world_rot = matmul3(base_rots[:, None], rot[:, :-1])
    world_pos = base_pos[:, None, :] + matvec3(base_rots[:, None], pos[:, :-1])
    return world_rot, world_pos


def jacobian_and_value(f, x):
    """``(jax.jacfwd(f)(x), f(x))`` from one forward pass (``f``'s value is a pytree)."""

    def both(y):
        value = f(y)
        return value, value

    return jax.jacfwd(both, has_aux=True)(x)


def contract(cotangent, tree):
    """``sum`` over the leaves of ``cotangent . leaf``, contracting every axis of the cotangent's
    leaf (a scalar for a value, a vector along ``x`` for a Jacobian)."""
    leaves = zip(jax.tree_util.tree_leaves(cotangent), jax.tree_util.tree_leaves(tree), strict=True)
    return sum(jnp.tensordot(lt, x, axes=lt.ndim, precision=MATMUL_PRECISION) for lt, x in leaves)


def index_runs(flat_index: np.ndarray) -> tuple[tuple[int, int], ...]:
    """``flat_index`` as runs ``(start, stop)`` of consecutive indices."""
    runs: list[list[int]] = []
    for i in np.asarray(flat_index, np.int64).tolist():
        if runs and runs[-1][1] == i:
            runs[-1][1] = i + 1
        else:
            runs.append([i, i + 1])
    return tuple((a, b) for a, b in runs)


def take_runs(grid_values: Array, runs) -> Array:
    """Rows ``runs`` of the flattened ``(segments, width, ...)`` grid, as a concatenation of
    static slices. A gather would become a scatter under reverse mode (serial on XLA:CPU, and it
    does not batch), and a one-hot product costs points x grid multiplications per value (it
    dominated the Hessian of the paper's robot)."""
    flat = grid_values.reshape((-1,) + grid_values.shape[2:])
    return jnp.concatenate([flat[a:b] for a, b in runs])


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
        self.runs = index_runs(self.flat_index)

    def grid(self, s: Float[Array, " p"], dtype) -> Float[Array, "n w"]:
        """The padded ``(segments, width)`` grid of ``s`` values (padding at ``s = 1``)."""
        flat = jnp.ones(self.n_segments * self.width, dtype)
        flat = flat.at[self.flat_index].set(jnp.asarray(s, dtype))
        return flat.reshape(self.n_segments, self.width)

    def select(self, grid_values: Array) -> Array:
        """Values at the listed points from values on the grid."""
        return take_runs(grid_values, self.runs)


def chain_segments(
    end_rot: Float[Array, "n 3 3"],
    end_pos: Float[Array, "n 3"],
    base_rotation: Float[Array, "3 3"],
    base_position: Float[Array, "3"],
) -> tuple[Float[Array, "n 3 3"], Float[Array, "n 3"]]:
    """World frames of the segments' bases from their local end frames.

    Composing rigid transforms is associative, so the chain is a parallel prefix
    (``jax.lax.associative_scan``: ``log2(n)`` batched products), not a sequential scan: its
    second derivatives, which the solver's Hessian takes, then hold no loop (XLA:CPU runs a
    loop's iterations as separate small kernels).
    """

    def compose(first, second):
        r1, p1 = first
        r2, p2 = second
        return matmul3(r1, r2), p1 + matvec3(r1, p2)

    dtype = end_rot.dtype
    rots = jnp.concatenate([base_rotation.astype(dtype)[None], end_rot[:-1]])
    pos = jnp.concatenate([base_position.astype(dtype)[None], end_pos[:-1]])
    return jax.lax.associative_scan(compose, (rots, pos))


class Knots:
    """Static cut of every segment at the points ``(segment, s)`` with known ``s``.

    ``s`` (``(n_segments, width)``) holds each segment's sorted knots from 0 to 1, padded with 1
    (empty intervals); ``flat_index`` is each requested point's index in the flattened grid.
    """

    def __init__(self, n_segments: int, segments, s, config: KinematicsConfig):
        min_intervals = config.min_intervals
        segments = np.asarray(segments, np.int64).reshape(-1)
        s = np.asarray(s, float).reshape(-1)
        rows = []
        for i in range(n_segments):
            cuts = np.sort(np.clip(np.concatenate([[0.0, 1.0], s[segments == i]]), 0.0, 1.0))
            cuts = cuts[np.concatenate([[True], np.diff(cuts) > _KNOT_MERGE])]
            cuts[-1] = 1.0
            # Intervals longer than 1 / min_intervals are split evenly.
            pieces = [
                np.linspace(lo, hi, int(np.ceil((hi - lo) * min_intervals - 1e-9)) + 1)[:-1]
                for lo, hi in zip(cuts[:-1], cuts[1:], strict=True)
            ]
            rows.append(np.concatenate(pieces + [[1.0]]))
        self.width = max(len(r) for r in rows)
        self.s = np.stack([np.pad(r, (0, self.width - len(r)), constant_values=1.0) for r in rows])
        self.n_segments = n_segments
        index = np.empty(len(s), np.int64)
        for k, (i, v) in enumerate(zip(segments, s, strict=True)):
            index[k] = i * self.width + int(np.argmin(np.abs(rows[i] - v)))
        self.flat_index = index
        self.interval_nodes = config.interval_nodes
        nodes, _ = gauss_legendre(self.interval_nodes)
        lo = self.s[:, :-1, None]
        self.node_s = lo + (self.s[:, 1:, None] - lo) * nodes  # (n, intervals, nodes)
        self.runs = index_runs(index)

    def select(self, grid_values: Array) -> Array:
        """Values at the requested points from values on the knot grid."""
        return take_runs(grid_values, self.runs)


def segment_knot_frames(
    model: StrainModel,
    q: Float[Array, " d"],
    length: Float[Array, ""],
    knots: Float[Array, " k"],
    node_weights: Float[Array, "i n"] | None = None,
    *,
    interval_nodes: int,
) -> tuple[Float[Array, "k 3 3"], Float[Array, "k 3"], Float[Array, "3"] | None]:
    """Rotations and positions (m) at the knots of one segment, in its base frame, the
    positions by ``interval_nodes`` Gauss-Legendre nodes per interval.

    With ``node_weights`` ``W(s)`` at the position nodes (:attr:`Knots.node_s`), also the
    weighted tangent integral ``(L + dL) int_0^1 W(s) R(s) e_z ds``.
    """
    dtype = q.dtype
    a = knots[:-1]
    h = knots[1:] - a
    nodes, weights = gauss_legendre(interval_nodes)
    nodes = jnp.asarray(nodes, dtype)
    n_int = a.shape[0]
    s_nodes = a[:, None] + h[:, None] * nodes[None, :]
    closed = model.plane_frames(q, knots)
    if closed is not None:
        # One bending plane: closed-form frames, no Magnus steps and no chained products. The
        # nodes need their tangents only (their rotations, unused, are left out of the program).
        rots = closed[0]
        tangents = model.plane_frames(q, s_nodes.reshape(-1))[1].reshape(s_nodes.shape + (3,))
        return _knot_positions(model, q, length, h, weights, rots, tangents, node_weights)
    # Magnus vectors of every interval and of [a, node] for every position node, in one vmap.
    starts = jnp.concatenate([a, jnp.repeat(a, len(nodes))])
    widths = jnp.concatenate([h, (h[:, None] * nodes[None, :]).reshape(-1)])
    omegas = jax.vmap(lambda a_, h_: _magnus_step(model, q, a_, h_))(starts, widths)
    steps = jax.vmap(exp_so3)(omegas[:n_int])
    node_dirs = rotate_ez(omegas[n_int:]).reshape(n_int, len(nodes), 3)

    base = model.base_rotation(q)
    first = jnp.eye(3, dtype=dtype) if base is None else base

    def accumulate(r, step):
        r_next = matmul3(r, step)
        return r_next, r_next

    _, rest = jax.lax.scan(accumulate, first, steps)
    rots = jnp.concatenate([first[None], rest])
    tangents = jnp.einsum("kij,knj->kni", rots[:-1], node_dirs, precision=MATMUL_PRECISION)
    return _knot_positions(model, q, length, h, weights, rots, tangents, node_weights)


def _knot_positions(model, q, length, h, weights, rots, tangents, node_weights):
    """Knot positions (and the weighted tangent integral) from the tangents at the position
    nodes of every interval (``(intervals, nodes, 3)``)."""
    pos, moment = _tangent_sums(h, weights, tangents, node_weights)
    ell = length + model.elongation(q)
    return rots, ell * pos, None if moment is None else ell * moment


def _tangent_sums(h, weights, tangents, node_weights):
    """Knot positions and weighted tangent integral per unit length of the segment: linear in
    the tangents at the position nodes (``(intervals, nodes, 3)``)."""
    dtype = tangents.dtype
    w = jnp.asarray(weights, dtype)
    steps_pos = h[:, None] * jnp.einsum("n,kni->ki", w, tangents, precision=MATMUL_PRECISION)
    pos = jnp.concatenate([jnp.zeros((1, 3), dtype), jnp.cumsum(steps_pos, axis=0)])
    if node_weights is None:
        return pos, None
    return pos, jnp.einsum("k,kn,kni->i", h, node_weights * w, tangents, precision=MATMUL_PRECISION)


def has_plane_derivatives(model: StrainModel) -> bool:
    """Whether :func:`segment_knot_jacobian` and :func:`segment_knot_curvature` apply."""
    return model.plane_angle_basis(np.zeros(1)) is not None


def _plane_points(model, q, knots, interval_nodes: int):
    """The bending angles and their bases at the knots and at the position nodes."""
    dtype = q.dtype
    a = knots[:-1]
    h = knots[1:] - a
    nodes, weights = gauss_legendre(interval_nodes)
    s_nodes = a[:, None] + h[:, None] * jnp.asarray(nodes, dtype)[None, :]
    return (
        (model.bending_angle(q, knots), model.plane_angle_basis(knots)),
        (model.bending_angle(q, s_nodes), model.plane_angle_basis(s_nodes)),
        h,
        weights,
    )


def _knots_and_nodes(model, theta_k, theta_n, phi, order: int):
    """:meth:`pacjax._model.strain.PlanarCurvature.plane_rotation_jet` at the knots and at the
    position nodes, in one evaluation."""
    k = theta_k.shape[0]
    jet = model.plane_rotation_jet(jnp.concatenate([theta_k, theta_n.reshape(-1)]), phi, order)
    return [r[:k] for r in jet], [r[k:].reshape(theta_n.shape + (3, 3)) for r in jet]


def _angle_jacobian(basis):
    """``d (theta, phi) / d q`` at each point (``(*p, 2, d)``) from ``d theta / d q[:m]``."""
    m = basis.shape[-1]
    shape = basis.shape[:-1]
    zeros = jnp.zeros(shape + (1,), basis.dtype)
    row_theta = jnp.concatenate([basis, zeros, zeros], axis=-1)
    row_phi = jnp.concatenate([jnp.zeros(shape + (m,), basis.dtype), zeros + 1.0, zeros], axis=-1)
    return jnp.stack([row_theta, row_phi], axis=-2)


def segment_knot_jacobian(
    model: StrainModel,
    q: Float[Array, " d"],
    length: Float[Array, ""],
    knots: Float[Array, " k"],
    node_weights: Float[Array, "i n"] | None = None,
    *,
    interval_nodes: int,
):
    """:func:`segment_knot_frames` and its Jacobian along ``q`` (``(jacobian, value)``, the
    layout of ``jax.jacfwd(..., has_aux=True)``) for a model whose frames depend on ``q``
    only through the bending angle ``theta(s)``, linear in the curvature coordinates, and the
    plane angle ``phi`` (:meth:`StrainModel.plane_angle_basis`). The rotations and tangents are
    differentiated point by point along ``(theta, phi)`` alone; the positions are linear in the
    tangents and proportional to the segment's length ``L + dL``."""
    phi = q[-2]
    (theta_k, basis_k), (theta_n, basis_n), h, weights = _plane_points(
        model, q, knots, interval_nodes
    )

    knot_jet, node_jet = _knots_and_nodes(model, theta_k, theta_n, phi, order=1)
    rots, d_rot = knot_jet[0], jnp.stack(knot_jet[1:], axis=-1)
    tangents, tan_t, tan_p = (r[..., :, 2] for r in node_jet)
    d_tan = jnp.stack([tan_t, tan_p], axis=-1)
    # Chain rule through (theta, phi)(q).
    d_rot = jnp.einsum(
        "kija,kad->kijd", d_rot, _angle_jacobian(basis_k), precision=MATMUL_PRECISION
    )
    d_tan = jnp.einsum(
        "inxa,inad->inxd", d_tan, _angle_jacobian(basis_n), precision=MATMUL_PRECISION
    )
    ell = length + model.elongation(q)
    pos, moment = _tangent_sums(h, weights, tangents, node_weights)
    d_pos, d_moment = jax.vmap(
        lambda t: _tangent_sums(h, weights, t, node_weights), in_axes=-1, out_axes=-1
    )(d_tan)
    # d (ell x) / d dL = x.
    d_pos = (ell * d_pos).at[..., -1].add(pos)
    value = (rots, ell * pos, None if moment is None else ell * moment)
    if moment is None:
        return (d_rot, d_pos, None), value
    d_moment = (ell * d_moment).at[..., -1].add(moment)
    return (d_rot, d_pos, d_moment), value


def segment_knot_curvature(
    model: StrainModel,
    q: Float[Array, " d"],
    length: Float[Array, ""],
    knots: Float[Array, " k"],
    node_weights: Float[Array, "i n"] | None,
    lam: tuple,
    *,
    interval_nodes: int,
) -> Float[Array, "d d"]:
    """Hessian along ``q`` of ``lam . segment_knot_frames(q)`` (``lam`` a cotangent of its
    value: rotations, positions, weighted tangent integral) for the models of
    :func:`segment_knot_jacobian`. The position terms are a weighted sum of tangents,
    ``(L + dL) sum_p beta_p . T(theta_p, phi)``, so the whole Hessian comes from 2 x 2
    Hessians at the points, mapped through ``(theta, phi)(q)`` (linear)."""
    lam_rot, lam_pos, lam_moment = lam
    phi = q[-2]
    (theta_k, basis_k), (theta_n, basis_n), h, weights = _plane_points(
        model, q, knots, interval_nodes
    )
    w = jnp.asarray(weights, q.dtype)
    # Interval j's tangents reach every knot after it: beta = h w (sum_{k > j} lam_pos_k + W nu).
    beyond = jnp.cumsum(lam_pos[::-1], axis=0)[::-1][1:]
    beta = beyond[:, None, :]
    if lam_moment is not None:
        beta = beta + node_weights[:, :, None] * lam_moment
    beta = (h[:, None] * w[None, :])[:, :, None] * beta

    def symmetric(tt, tp, pp):
        return jnp.stack([jnp.stack([tt, tp], -1), jnp.stack([tp, pp], -1)], -2)

    # lam . R and beta . (R e_z), differentiated twice along (theta, phi) point by point.
    rot_jet, tangent_jet = _knots_and_nodes(model, theta_k, theta_n, phi, order=2)
    h_rot = symmetric(*(jnp.sum(lam_rot * r, axis=(-2, -1)) for r in rot_jet[3:]))
    tan_jet = [jnp.sum(beta * r[..., :, 2], axis=-1) for r in tangent_jet]
    h_tan = symmetric(*tan_jet[3:])
    g_tan = jnp.stack(tan_jet[1:3], axis=-1)
    a_k = _angle_jacobian(basis_k)
    a_n = _angle_jacobian(basis_n)
    ell = length + model.elongation(q)
    hessian = jnp.einsum("kai,kab,kbj->ij", a_k, h_rot, a_k, precision=MATMUL_PRECISION)
    hessian = hessian + ell * jnp.einsum(
        "nmai,nmab,nmbj->ij", a_n, h_tan, a_n, precision=MATMUL_PRECISION
    )
    # d2 / d dL dq of ell x: the first derivative of the tangent sum.
    cross = jnp.einsum("nma,nmai->i", g_tan, a_n, precision=MATMUL_PRECISION)
    hessian = hessian.at[-1, :].add(cross).at[:, -1].add(cross)
    return hessian


def knot_frames(
    model: StrainModel,
    q: Float[Array, "n d"],
    lengths: Float[Array, " n"],
    base_rotation: Float[Array, "3 3"],
    base_position: Float[Array, "3"],
    knots: Knots,
    node_weights: Float[Array, "n i m"] | None = None,
) -> tuple[Float[Array, "n k 3 3"], Float[Array, "n k 3"], tuple]:
    """World frames at every knot; the world frames of the segments' bases; and, with
    ``node_weights``, each segment's weighted tangent integral in the world frame."""
    grid = jnp.asarray(knots.s, q.dtype)
    rot, pos, moment = jax.vmap(
        lambda qi, li, ki, wi: segment_knot_frames(
            model, qi, li, ki, wi, interval_nodes=knots.interval_nodes
        ),
    )(q, lengths, grid, node_weights)
    base_rot, base_pos = chain_segments(rot[:, -1], pos[:, -1], base_rotation, base_position)
    world_rot = matmul3(base_rot[:, None], rot)
    world_pos = base_pos[:, None, :] + matvec3(base_rot[:, None], pos)
    if moment is not None:
        moment = matvec3(base_rot, moment)
    return world_rot, world_pos, (base_rot, base_pos, moment)
