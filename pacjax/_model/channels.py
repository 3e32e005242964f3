"""Tendons in continuous channels: length as the arc length of the tendon curve.

A channel holds its tendon at ``r(s) = rho(s) (cos alpha(s), sin alpha(s), 0)`` in the
cross-section frame all along the route, ``rho`` and ``alpha`` linear in the route coordinate
(a tapered or helical channel). With the backbone ``p' = (L + dL) R e_z`` and ``R' = R [u]x``
(per unit normalised ``s``), the tendon curve ``p + R r`` has

``d(p + R r)/ds = R ((L + dL) e_z + u x r + r')``,

so its length in a segment, ``int |(L + dL) e_z + u(s) x r(s) + r'(s)| ds``, depends on that
segment's strain only: not on its frames, nor on any other segment. It is integrated by
Gauss-Legendre on the part of the segment the tendon crosses, at the nodes of the elastic
energy's rule, and enters the energy as a per-segment part of the tendon's length, like the
chords of :class:`pacjax._model.tendons.LocalChords`. Its derivatives are those of this small
function of the segment's coordinates (``d`` of them), taken exactly by automatic
differentiation.
"""

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import MATMUL_PRECISION
from .quadrature import gauss_legendre
from .strain import StrainModel


class ChannelRouting:
    """The channel tendons of a scene per segment (static layout; tendon indices are the
    scene's, ring tendons have no entry). Per segment, ``slots`` channel rows (padded): the
    part ``[0, span]`` of the segment the tendon crosses, and its route fractions there."""

    def __init__(self, tendons, n_segments: int, routings=("channel",)):
        """``routings``: which tendons to lay out (``("channel", "rings")``: ring tendons too,
        as the channel through their rings)."""
        self.tendon_ids = [i for i, t in enumerate(tendons) if t.routing in routings]
        c, m = len(self.tendon_ids), len(tendons)
        self.span = np.ones((n_segments, c))
        self.mask = np.zeros((n_segments, c))
        self.fraction = np.zeros((n_segments, c, 2))
        self.tendon = np.zeros((c, m))
        for j, t_id in enumerate(self.tendon_ids):
            t = tendons[t_id]
            self.tendon[j, t_id] = 1.0
            for k in range(t.entry_segment, t.segment + 1):
                end = t.s if k == t.segment else 1.0
                self.span[k, j] = end
                self.mask[k, j] = 1.0
                self.fraction[k, j] = (t.route_fraction(k, 0.0), t.route_fraction(k, end))

    def __bool__(self):
        return bool(self.tendon_ids)

    def geometry(self, tendons, dtype) -> dict:
        """Per-segment inputs of :func:`segment_channel_parts` (leading axis: segments): the
        channels' radius and angle at both ends of each crossed part (traced: they are scene
        parameters) and the static layout."""
        chosen = [tendons[i] for i in self.tendon_ids]

        def ends(start, end):
            start = jnp.stack(start).astype(dtype)
            end = jnp.stack(end).astype(dtype)
            frac = jnp.asarray(self.fraction, dtype)
            return start[:, None] + (end - start)[:, None] * frac  # (n, c, 2)

        radius = ends(
            [t.offset for t in chosen],
            [t.anchor_offset for t in chosen],
        )
        angle = ends(
            [t.angle for t in chosen],
            [t.anchor_angle for t in chosen],
        )
        n = self.span.shape[0]
        return {
            "radius": radius,
            "angle": angle,
            "span": jnp.asarray(self.span, dtype),
            "mask": jnp.asarray(self.mask, dtype),
            "tendon": jnp.broadcast_to(jnp.asarray(self.tendon, dtype), (n, *self.tendon.shape)),
        }


def segment_channel_parts(
    model: StrainModel,
    qi: Float[Array, " d"],
    length: Float[Array, ""],
    channels: dict,
    quadrature_points: int,
) -> Float[Array, " m"]:
    """Each tendon's length (m) inside one segment from its channel (zero for tendons that do
    not cross it or run through rings). ``channels``: one segment's row of
    :meth:`ChannelRouting.geometry`."""
    dtype = qi.dtype
    nodes, weights = (jnp.asarray(a, dtype) for a in gauss_legendre(quadrature_points))
    span = channels["span"]  # (c,)
    radius, angle = channels["radius"], channels["angle"]  # (c, 2)
    rho = radius[:, :1] + (radius[:, 1:] - radius[:, :1]) * nodes  # (c, g)
    alpha = angle[:, :1] + (angle[:, 1:] - angle[:, :1]) * nodes
    ca, sa = jnp.cos(alpha), jnp.sin(alpha)
    # r and dr/ds in the cross-section frame (its z component is zero).
    rx, ry = rho * ca, rho * sa
    d_rho = ((radius[:, 1] - radius[:, 0]) / span)[:, None]
    d_alpha = ((angle[:, 1] - angle[:, 0]) / span)[:, None]
    drx, dry = d_rho * ca - rho * d_alpha * sa, d_rho * sa + rho * d_alpha * ca
    strain = jax.vmap(jax.vmap(model.strain, in_axes=(None, 0)), in_axes=(None, 0))(
        qi, span[:, None] * nodes
    )  # (c, g, 3)
    ux, uy, uz = strain[..., 0], strain[..., 1], strain[..., 2]
    # (L + dL) e_z + u x r + r'
    vx = -uz * ry + drx
    vy = uz * rx + dry
    vz = length + model.elongation(qi) + ux * ry - uy * rx
    speed = jnp.sqrt(vx * vx + vy * vy + vz * vz)
    inside = span * jnp.matmul(speed, weights, precision=MATMUL_PRECISION)  # (c,)
    return jnp.matmul(channels["mask"] * inside, channels["tendon"], precision=MATMUL_PRECISION)


class RingStretches:
    """The stretches between consecutive guide rings of the ring-routed tendons, cut into
    pieces at segment ends (static arrays): the layout of :func:`ring_chord_sag`."""

    def __init__(self, tendons):
        seg, a, b, stretch, owner, middle = [], [], [], [], [], []
        for t_id, t in enumerate(tendons):
            if t.routing != "rings":
                continue
            route = t.route()
            for (ka, sa), (kb, sb) in zip(route[:-1], route[1:], strict=True):
                for k in range(ka, kb + 1):
                    lo, hi = (sa if k == ka else 0.0), (sb if k == kb else 1.0)
                    if hi > lo:
                        seg.append(k)
                        a.append(lo)
                        b.append(hi)
                        stretch.append(len(owner))
                owner.append(t_id)
                middle.append(0.5 * (t.route_fraction(ka, sa) + t.route_fraction(kb, sb)))
        self.segment = np.asarray(seg, np.int32)
        self.a, self.b = np.asarray(a, float), np.asarray(b, float)
        self.stretch = np.asarray(stretch, np.int32)
        self.owner = np.asarray(owner, np.int32)
        self.middle = np.asarray(middle, float)

    def __bool__(self):
        return len(self.owner) > 0


def ring_chord_sag(scene, q: Float[Array, " n_dofs"]) -> Float[Array, " m"]:
    """For each ring-routed tendon, the largest sag of a chord below the channel through the
    same rings, relative to the tendon's offset there (zero for channel tendons): how far short
    of the channel's moment arm the chords fall.

    A chord across a stretch of arc ``a`` over which the backbone turns by ``dtheta`` sags
    ``a dtheta / 8`` below the arc at its middle, where the channel's offset is ``r``: the
    chord's moment arm there is short by ``a dtheta / (8 r)``. From the strain alone (no
    frames), all stretches at once: cheap enough to check after every solve.
    """
    dtype = q.dtype
    layout = RingStretches(scene.tendons)
    if not layout:
        return jnp.zeros(scene.n_tendons, dtype)
    coords = scene.coordinates(q)[layout.segment]  # (p, d)
    nodes, weights = (jnp.asarray(x, dtype) for x in gauss_legendre(2))
    a, b = jnp.asarray(layout.a, dtype), jnp.asarray(layout.b, dtype)
    s = a[:, None] + (b - a)[:, None] * nodes  # (p, 2)
    u = jax.vmap(jax.vmap(scene.model.strain, in_axes=(None, 0)))(coords, s)
    turn = (b - a) * jnp.matmul(jnp.hypot(u[..., 0], u[..., 1]), weights)
    length = scene.robot.stacked("length").astype(dtype)[layout.segment]
    arc = (length + jax.vmap(scene.model.elongation)(coords)) * (b - a)
    n = len(layout.owner)
    turn = jax.ops.segment_sum(turn, layout.stretch, num_segments=n)
    arc = jax.ops.segment_sum(arc, layout.stretch, num_segments=n)
    start = jnp.stack([t.offset for t in scene.tendons]).astype(dtype)
    end = jnp.stack([t.anchor_offset for t in scene.tendons])
    owner = layout.owner
    offset = start[owner] + (end.astype(dtype) - start)[owner] * jnp.asarray(layout.middle, dtype)
    sag = arc * turn / (8.0 * offset)
    worst = jax.ops.segment_max(sag, owner, num_segments=scene.n_tendons)
    return jnp.maximum(worst, 0.0)
