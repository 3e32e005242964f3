"""Tendons: routing through guide rings, length, tension and energy.

A tendon runs from its entry (the robot's base for a free tendon, the base of its own segment
for one in a Bowden cable) to its anchor, either through guide rings at fixed ``s`` values (its
length is the sum of straight chords between consecutive guide points: frictionless pulleys) or
in a continuous channel inside the body (its length is the arc length of the tendon curve:
:mod:`pacjax._model.channels`).

In length mode the motor holds the commanded length ``l_bar = l_rest - u`` with gain
``kappa_P``: tension ``kappa_P max(l - l_bar, 0)`` and energy ``1/2 kappa_P max(l - l_bar, 0)^2``.
The energy is C1 with a Lipschitz gradient, enough for the Newton-type solvers (the Hessian jumps
where a tendon goes slack, which a line search handles). Tendons never push. In tension mode
the control is the tension ``T >= 0`` (N) and the energy is ``T l``.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import MATMUL_PRECISION
from .values import as_float, check_finite, check_positive, check_scalar, float_field

MODES = ("length", "tension")
ROUTINGS = ("rings", "channel")
DEFAULT_GUIDES = tuple(np.linspace(0.0, 1.0, 11).tolist())


def _static_float(name: str, value) -> float:
    """A static (routing) number as a Python float, naming ``name`` on bad input."""
    if isinstance(value, (bool, np.bool_, str, bytes)) or np.ndim(value) != 0:
        raise TypeError(f"{name} must hold plain numbers, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must hold plain numbers, got {value!r}") from None


class Tendon(eqx.Module):
    """A tendon. SI units.

    Args:
        segment: index of the segment holding the anchor.
        angle: angle (rad) of the tendon around the cross-section, from the x axis.
        offset: radial distance (m) of the tendon from the backbone at its entry.
        s: anchor position within ``segment``, in ``(0, 1]``.
        offset_end: radial distance (m) at the anchor (a tapered body); linear along the route
            (in the route coordinate ``segment index + s``). Default: ``offset``.
        bowden: True when the tendon reaches its segment through a Bowden cable and acts on
            that segment only; False when it runs through every proximal segment.
        guides: ``s`` values of the guide rings in each segment it crosses (default: 11 evenly
            spaced rings including both ends). Rings only.
        mode: ``"length"`` (motor holds a commanded length) or ``"tension"`` (control is a
            tension in N).
        gain: ``kappa_P`` (N/m), required in length mode.
        routing: ``"rings"`` (straight chords between guide rings, the paper's robot) or
            ``"channel"`` (a continuous channel inside the body: the tendon follows the curve
            at ``offset`` and ``angle`` from the backbone all along its route).
        angle_end: angle (rad) at the anchor, linear along the route like the offset: a helical
            channel. Default: ``angle``. Channels only (a ring tendon's holes are all at
            ``angle``).
    """

    segment: int = eqx.field(static=True)
    angle: Float[Array, ""] = eqx.field(converter=float_field("Tendon.angle"))
    offset: Float[Array, ""] = eqx.field(converter=float_field("Tendon.offset"))
    s: float = eqx.field(static=True, default=1.0)
    offset_end: Float[Array, ""] | None = None
    bowden: bool = eqx.field(static=True, default=False)
    guides: tuple[float, ...] = eqx.field(static=True, default=DEFAULT_GUIDES)
    mode: str = eqx.field(static=True, default="length")
    gain: Float[Array, ""] | None = None
    routing: str = eqx.field(static=True, default="rings")
    angle_end: Float[Array, ""] | None = None

    def __init__(
        self,
        segment,
        angle,
        offset,
        s=1.0,
        offset_end=None,
        bowden=False,
        guides=None,
        mode="length",
        gain=None,
        routing="rings",
        angle_end=None,
    ):
        if not isinstance(segment, (int, np.integer)) or isinstance(segment, bool):
            raise TypeError(f"Tendon.segment must be an integer index, got {segment!r}")
        self.segment = int(segment)
        self.angle = angle
        self.offset = offset
        self.s = _static_float("Tendon.s", s)
        self.offset_end = None if offset_end is None else as_float(offset_end, "Tendon.offset_end")
        if not isinstance(bowden, (bool, np.bool_)):
            raise TypeError(f"Tendon.bowden must be True or False, got {bowden!r}")
        self.bowden = bool(bowden)
        if routing not in ROUTINGS:
            raise ValueError(f"Tendon.routing must be one of {ROUTINGS}, got {routing!r}")
        self.routing = routing
        if routing == "channel" and guides is not None:
            raise ValueError("Tendon.guides applies to routing='rings' only (a channel has none)")
        if routing == "rings" and angle_end is not None:
            raise ValueError(
                "Tendon.angle_end applies to routing='channel' only (a ring tendon's holes lie "
                "at one angle)"
            )
        self.angle_end = None if angle_end is None else as_float(angle_end, "Tendon.angle_end")
        if guides is None:
            guides = DEFAULT_GUIDES
        elif isinstance(guides, (str, bytes)) or not np.iterable(guides):
            raise TypeError(f"Tendon.guides must be a sequence of s values, got {guides!r}")
        self.guides = tuple(_static_float("Tendon.guides", g) for g in guides)
        self.mode = mode
        self.gain = None if gain is None else as_float(gain, "Tendon.gain")

    def __check_init__(self):
        if self.segment < 0:
            raise ValueError(f"Tendon.segment must be >= 0, got {self.segment}")
        if not 0.0 < self.s <= 1.0:
            raise ValueError(f"Tendon.s (anchor) must lie in (0, 1], got {self.s}")
        if not self.guides or any(not 0.0 <= g <= 1.0 for g in self.guides):
            raise ValueError(f"Tendon.guides must be s values in [0, 1], got {self.guides}")
        if self.mode not in MODES:
            raise ValueError(f"Tendon.mode must be one of {MODES}, got {self.mode!r}")
        for field in ("angle", "offset"):
            check_scalar(f"Tendon.{field}", getattr(self, field))
        check_finite("Tendon.angle", self.angle)
        check_positive("Tendon.offset", self.offset, allow_zero=True)
        if self.offset_end is not None:
            check_scalar("Tendon.offset_end", self.offset_end)
            check_positive("Tendon.offset_end", self.offset_end, allow_zero=True)
        if self.angle_end is not None:
            check_scalar("Tendon.angle_end", self.angle_end)
            check_finite("Tendon.angle_end", self.angle_end)
        if self.mode == "length" and self.gain is None:
            raise ValueError("Tendon.gain (kappa_P, N/m) is required for a length-mode tendon")
        if self.gain is not None:  # checked in tension mode too: a NaN is never silently kept
            check_scalar("Tendon.gain", self.gain)
            check_positive("Tendon.gain", self.gain)

    @property
    def anchor_offset(self) -> Float[Array, ""]:
        """Radial distance (m) at the anchor: ``offset_end``, or ``offset`` when not tapered."""
        return self.offset if self.offset_end is None else self.offset_end

    @property
    def anchor_angle(self) -> Float[Array, ""]:
        """Angle (rad) at the anchor: ``angle_end``, or ``angle`` when not helical."""
        return self.angle if self.angle_end is None else self.angle_end

    @property
    def entry_segment(self) -> int:
        """The segment at whose base the tendon enters the body."""
        return self.segment if self.bowden else 0

    def route_fraction(self, segment: int, s: float) -> float:
        """Where ``(segment, s)`` lies along the route, from 0 (entry) to 1 (anchor), in the
        route coordinate ``segment index + s`` in which offset and angle are linear."""
        start = self.entry_segment
        return (segment + s - start) / (self.segment + self.s - start)

    def route(self) -> list[tuple[int, float]]:
        """Guide points ``(segment, s)`` from the entry ring to the anchor."""
        start = self.entry_segment
        points: list[tuple[int, float]] = []
        for k in range(start, self.segment + 1):
            ring_s = sorted(set(self.guides) | ({0.0} if k == start else set()))
            if k == self.segment:
                ring_s = [g for g in ring_s if g < self.s] + [self.s]
            for g in ring_s:
                # The ring at s = 1 of one segment is the ring at s = 0 of the next.
                if points and g == 0.0 and points[-1] == (k - 1, 1.0):
                    continue
                points.append((k, g))
        return points


class TendonRouting:
    """The ring-routed tendons of a scene flattened into guide points and chords (static index
    arrays; tendon indices are the scene's, channel tendons have no points).

    Built from the tendons' static routing only, so it is rebuilt cheaply at trace time.
    """

    def __init__(self, tendons):
        segs, ss, ids, fracs, starts, chord_ids = [], [], [], [], [], []
        for t_id, tendon in enumerate(tendons):
            if tendon.routing != "rings":
                continue
            route = tendon.route()
            frac = [tendon.route_fraction(k, s) for k, s in route]
            first = len(segs)
            for (k, s), f in zip(route, frac, strict=True):
                segs.append(k)
                ss.append(s)
                ids.append(t_id)
                fracs.append(f)
            starts.extend(range(first, first + len(route) - 1))
            chord_ids.extend([t_id] * (len(route) - 1))
        self.point_segment = np.asarray(segs, np.int32)
        self.point_s = np.asarray(ss, float)
        self.point_tendon = np.asarray(ids, np.int32)
        self.point_route_fraction = np.asarray(fracs, float)
        self.chord_start = np.asarray(starts, np.int32)
        self.chord_tendon = np.asarray(chord_ids, np.int32)
        self.n_tendons = len(tendons)

    def __bool__(self):
        return len(self.point_segment) > 0

    def local_offsets(self, tendons, dtype) -> Float[Array, "p 3"]:
        """Guide point offsets (m) in their cross-section frames."""
        angle = jnp.stack([t.angle for t in tendons]).astype(dtype)[self.point_tendon]
        start = jnp.stack([t.offset for t in tendons]).astype(dtype)
        end = jnp.stack([t.anchor_offset for t in tendons])
        frac = jnp.asarray(self.point_route_fraction, dtype)
        radius = start[self.point_tendon] + (end.astype(dtype) - start)[self.point_tendon] * frac
        return jnp.stack(
            [radius * jnp.cos(angle), radius * jnp.sin(angle), jnp.zeros_like(angle)], -1
        )

    def lengths(self, points: Float[Array, "p 3"]) -> Float[Array, " m"]:
        """Tendon lengths (m) from guide point positions."""
        chords = points[self.chord_start + 1] - points[self.chord_start]
        # Consecutive guide points are distinct (segment lengths are > 0), so the norm is smooth.
        chord_lengths = jnp.sqrt(jnp.sum(chords * chords, axis=-1))
        return jax.ops.segment_sum(chord_lengths, self.chord_tendon, num_segments=self.n_tendons)

    def rest_lengths(self, tendons, segment_lengths: Float[Array, " n"]) -> Float[Array, " m"]:
        """Tendon lengths (m) on the straight robot at rest (``q = 0``)."""
        dtype = segment_lengths.dtype
        offsets = self.local_offsets(tendons, dtype)
        seg_start = jnp.concatenate([jnp.zeros(1, dtype), jnp.cumsum(segment_lengths)])
        s = jnp.asarray(self.point_s, dtype)
        axial = seg_start[self.point_segment] + segment_lengths[self.point_segment] * s
        points = offsets.at[:, 2].set(axial)
        return self.lengths(points)


def tendon_energy(
    tendons, lengths: Float[Array, " m"], rest_lengths: Float[Array, " m"], controls
) -> Float[Array, ""]:
    """Potential energy (J) of the tendons and their motors."""
    energy = jnp.zeros((), lengths.dtype)
    length_ids = [i for i, t in enumerate(tendons) if t.mode == "length"]
    tension_ids = [i for i, t in enumerate(tendons) if t.mode == "tension"]
    if length_ids:
        idx = np.asarray(length_ids)
        gain = jnp.stack([tendons[i].gain for i in length_ids]).astype(lengths.dtype)
        stretch = lengths[idx] - (rest_lengths[idx] - controls[idx])
        energy = energy + 0.5 * jnp.sum(gain * jnp.maximum(stretch, 0.0) ** 2)
    if tension_ids:
        idx = np.asarray(tension_ids)
        energy = energy + jnp.sum(controls[idx] * lengths[idx])
    return energy


def tendon_tensions(
    tendons, lengths: Float[Array, " m"], rest_lengths: Float[Array, " m"], controls
) -> Float[Array, " m"]:
    """Tendon tensions (N): ``kappa_P max(l - l_bar, 0)`` in length mode, the control otherwise."""
    out = []
    for i, t in enumerate(tendons):
        if t.mode == "length":
            stretch = lengths[i] - (rest_lengths[i] - controls[i])
            out.append(t.gain.astype(lengths.dtype) * jnp.maximum(stretch, 0.0))
        else:
            out.append(controls[i].astype(lengths.dtype))
    return jnp.stack(out)


class LocalChords:
    """The tendons' chords, each written in the base frame of the one segment it lies in.

    A chord's length does not change when the whole segment moves, so a chord between two guide
    points of segment ``k`` (or from the ring at the end of segment ``k - 1``, which is the
    origin of segment ``k``'s base frame, to a guide point of segment ``k``) depends on
    segment ``k``'s coordinates only. Tendon lengths are then a sum of per-segment parts, and
    the energy's Hessian needs no chaining of segments for the tendons. :meth:`build` returns
    None when a chord spans a segment without a ring at its ends (the world-frame path then
    measures every chord).

    Per segment, ``slots`` chords (padded): each end's knot, whether the start is the base
    ring, which routing points give the offsets, and which tendon each chord belongs to.
    """

    def __init__(self, knot_a, base_a, knot_b, point_a, point_b, mask, tendon):
        self.knot_a, self.base_a, self.knot_b = knot_a, base_a, knot_b
        self.point_a, self.point_b, self.mask, self.tendon = point_a, point_b, mask, tendon

    @classmethod
    def build(cls, routing: TendonRouting, knot: np.ndarray, n_segments: int):
        """``knot``: each routing point's knot index within its segment."""
        owned: list[list[tuple]] = [[] for _ in range(n_segments)]
        for c, a in enumerate(routing.chord_start.tolist()):
            b = a + 1
            seg_a, seg_b = int(routing.point_segment[a]), int(routing.point_segment[b])
            if seg_a == seg_b:
                owned[seg_b].append((knot[a], False, knot[b], a, b, routing.chord_tendon[c]))
            elif seg_b == seg_a + 1 and routing.point_s[a] == 1.0:
                owned[seg_b].append((0, True, knot[b], a, b, routing.chord_tendon[c]))
            else:
                return None
        slots = max(1, max(len(o) for o in owned))
        shape = (n_segments, slots)
        knot_a, knot_b = np.zeros(shape, np.int32), np.zeros(shape, np.int32)
        base_a, mask = np.zeros(shape), np.zeros(shape)
        point_a, point_b = np.zeros(shape, np.int64), np.zeros(shape, np.int64)
        tendon = np.zeros(shape + (routing.n_tendons,))
        for i, chords in enumerate(owned):
            for j, (ka, is_base, kb, a, b, t) in enumerate(chords):
                knot_a[i, j], knot_b[i, j] = ka, kb
                base_a[i, j] = 1.0 if is_base else 0.0
                point_a[i, j], point_b[i, j] = a, b
                mask[i, j] = 1.0
                tendon[i, j, t] = 1.0
        return cls(knot_a, base_a, knot_b, point_a, point_b, mask, tendon)

    def inputs(self, offsets: Float[Array, "p 3"]) -> dict:
        """Per-segment arrays for :func:`segment_tendon_parts` (leading axis: segments)."""
        dtype = offsets.dtype
        return {
            "knot_a": jnp.asarray(self.knot_a),
            "base_a": jnp.asarray(self.base_a, dtype),
            "knot_b": jnp.asarray(self.knot_b),
            "offset_a": offsets[self.point_a],
            "offset_b": offsets[self.point_b],
            "mask": jnp.asarray(self.mask, dtype),
            "tendon": jnp.asarray(self.tendon, dtype),
        }


def _chord_ends(rot, pos, chords: dict, base: bool = True):
    """Start and end (``(c, 3)`` each) of every chord slot of one segment, in its base frame.

    Linear in ``(rot, pos)`` but for the offset of chords that start at the segment's base,
    which ``base=False`` leaves out (the map applied to derivatives of the frames)."""
    # The knots are gathered, not picked by a one-hot product: under the solver's vmap the
    # product was a batched matrix product per chord end, about a tenth of the linearisation.

    def ends(knot, offset):
        return pos[knot] + jnp.einsum("cij,cj->ci", rot[knot], offset, precision=MATMUL_PRECISION)

    base_a = chords["base_a"][:, None]
    start = (1.0 - base_a) * ends(chords["knot_a"], chords["offset_a"])
    if base:
        start = start + base_a * chords["offset_a"]
    return start, ends(chords["knot_b"], chords["offset_b"])


def _chord_lengths(start, end, mask):
    chord = end - start
    # Padding slots have no chord: a unit length there keeps the square root smooth.
    return jnp.sqrt(jnp.where(mask > 0, jnp.sum(chord * chord, axis=-1), 1.0))


def segment_tendon_parts(rot, pos, chords: dict) -> Float[Array, " m"]:
    """Each tendon's length (m) inside one segment, from the segment's local knot frames
    (``rot`` (k, 3, 3), ``pos`` (k, 3)) and its :meth:`LocalChords.inputs` row."""
    mask = chords["mask"]
    return jnp.matmul(
        mask * _chord_lengths(*_chord_ends(rot, pos, chords), mask),
        chords["tendon"],
        precision=MATMUL_PRECISION,
    )


class ChordDerivatives(eqx.Module):
    """The tendon parts of one segment with their first and second derivatives along the ``d``
    directions of the segment's knot-frame Jacobian (:func:`tendon_parts_derivatives`)."""

    parts: Float[Array, " m"]
    jacobian: Float[Array, "m d"]
    unit: Float[Array, "c 3"]
    length: Float[Array, " c"]
    d_chord: Float[Array, "c 3 d"]
    d_length: Float[Array, "c d"]

    def curvature(self, lam: Float[Array, " m"], rot, pos, chords: dict):
        """For weights ``lam`` on the parts: the Hessian of ``lam . parts`` along the frames'
        linearisation (``d x d``), and the gradient of ``lam . parts`` with respect to the
        frames ``(rot, pos)``, whose product with their second derivatives completes it.

        With chord vectors ``c``, lengths ``l = |c|``, unit ``u`` and ``C = dc``:
        ``d2 l = C^T (I - u u^T) C / l + u . d2c``, and ``d2c`` is linear in the frames'
        second derivatives (the chord ends are affine in the frames).
        """
        lam_c = chords["mask"] * (jnp.matmul(chords["tendon"], lam, precision=MATMUL_PRECISION))
        w = lam_c / self.length
        hessian = jnp.einsum(
            "c,cit,cis->ts", w, self.d_chord, self.d_chord, precision=MATMUL_PRECISION
        ) - jnp.einsum("c,ct,cs->ts", w, self.d_length, self.d_length, precision=MATMUL_PRECISION)
        force = lam_c[:, None] * self.unit
        _, pull = jax.vjp(lambda r, p: _chord_ends(r, p, chords, base=False), rot, pos)
        g_rot, g_pos = pull((-force, force))
        return hessian, (g_rot, g_pos)


def tendon_parts_derivatives(rot, pos, d_rot, d_pos, chords: dict) -> ChordDerivatives:
    """:func:`segment_tendon_parts` and its derivatives along the knot frames' Jacobian
    (``d_rot`` (k, 3, 3, d), ``d_pos`` (k, 3, d)), written out: the chord ends are affine in the
    frames, so their derivatives are the same map applied to the frames' derivatives."""
    mask = chords["mask"]
    start, end = _chord_ends(rot, pos, chords)
    length = _chord_lengths(start, end, mask)
    unit = (end - start) / length[:, None]
    d_start, d_end = jax.vmap(
        lambda r, p: _chord_ends(r, p, chords, base=False), in_axes=-1, out_axes=-1
    )(d_rot, d_pos)
    d_chord = d_end - d_start
    d_length = mask[:, None] * jnp.einsum("ci,cit->ct", unit, d_chord, precision=MATMUL_PRECISION)
    return ChordDerivatives(
        parts=jnp.matmul(mask * length, chords["tendon"], precision=MATMUL_PRECISION),
        jacobian=jnp.einsum("ct,cm->mt", d_length, chords["tendon"], precision=MATMUL_PRECISION),
        unit=unit,
        length=length,
        d_chord=d_chord,
        d_length=d_length,
    )
