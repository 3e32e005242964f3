"""Elastic, gravitational and external-load terms of the potential energy and residual."""

import jax
import jax.numpy as jnp
import jax.tree_util as jtu
from jaxtyping import Array, Float

from .._config import MATMUL_PRECISION
from .quadrature import gauss_legendre
from .robot import Robot, Segment
from .rotation import hat
from .strain import StrainModel


def section_stiffness(
    segment: Segment, quadrature_points: int, dtype
) -> tuple[Float[Array, " p"], Float[Array, " p"]]:
    """Bending and torsion stiffness (N m^2) at the elastic quadrature nodes (taper included,
    stiffening with contraction not: that depends on the configuration)."""
    nodes = jnp.asarray(gauss_legendre(quadrature_points)[0], dtype)
    bending = segment.bending_stiffness.astype(dtype) * jnp.ones_like(nodes)
    torsion = segment.torsion_stiffness.astype(dtype) * jnp.ones_like(nodes)
    profile = segment.bending_profile(nodes)
    if profile is not None:
        bending = bending * profile
        torsion = torsion * profile
    return bending, torsion


def _section_at(segment, quadrature_points, stiffness, elongation, dtype):
    """Gauss-Legendre nodes and weights, the length, and the bending (stiffened at
    ``elongation``) and torsion stiffness at the nodes (``stiffness``: :func:`section_stiffness`
    when already computed)."""
    nodes, weights = gauss_legendre(quadrature_points)
    length = segment.length.astype(dtype)
    if stiffness is None:
        stiffness = section_stiffness(segment, quadrature_points, dtype)
    bending, torsion = stiffness
    if segment.stiffening is not None:
        bending = bending * segment.stiffening(elongation, length)
    return jnp.asarray(nodes, dtype), jnp.asarray(weights, dtype), length, bending, torsion


def _bending_torsion_energy(model, length, weights, bending, torsion, strain):
    """``1/2 int_0^1 (EI |u_bend|^2 + GJ u_twist^2) / L ds`` of strain values at the nodes."""
    energy = 0.5 / length * jnp.sum(weights * bending * (strain[:, 0] ** 2 + strain[:, 1] ** 2))
    if model.has_twist_strain():
        energy = energy + 0.5 / length * jnp.sum(weights * torsion * strain[:, 2] ** 2)
    return energy


def segment_elastic_energy(
    model: StrainModel,
    segment: Segment,
    q: Float[Array, " d"],
    quadrature_points: int,
    stiffness: tuple[Float[Array, " p"], Float[Array, " p"]] | None = None,
    rest: Float[Array, " d"] | None = None,
) -> Float[Array, ""]:
    """Elastic energy (J) of one segment.

    ``1/2 int_0^1 (EI(s) |u_bend(s) - u0_bend(s)|^2 + GJ(s) (u_twist(s) - u0_twist(s))^2) / L
    ds + 1/2 k_a dL^2`` plus the model's energy on non-strain coordinates (PAC's
    ``1/2 k_phi phi^2``), with ``u0`` the strain of the rest coordinates ``rest`` (None:
    straight). With constant stiffness, no rest curvature and PAC's affine curvature this is
    exactly the paper's Hankel form ``1/2 k_b [c0 c1] H [c0 c1]^T``, ``k_b = EI / L``; a taper
    makes ``H`` the weighted Gram matrix. Gauss-Legendre with ``n`` points is exact up to
    polynomial degree ``2 n - 1``. ``stiffness``: :func:`section_stiffness`, when already
    computed.
    """
    elongation = model.elongation(q)
    nodes, weights, length, bending, torsion = _section_at(
        segment, quadrature_points, stiffness, elongation, q.dtype
    )
    strain = jax.vmap(model.strain, in_axes=(None, 0))(q, nodes)
    if rest is not None:
        # The strain's difference, not the coordinates': PCC/PAC's are polar.
        strain = strain - jax.vmap(model.strain, in_axes=(None, 0))(rest, nodes)
        q = q - rest  # the non-strain coordinates' energy, from their rest values
    energy = _bending_torsion_energy(model, length, weights, bending, torsion, strain)
    extra = model.coordinate_energy(q, segment.torsion_stiffness.astype(q.dtype) / length)
    if extra is not None:
        energy = energy + extra
    axial = segment.axial_stiffness.astype(q.dtype)
    stop = contraction_stop_energy(elongation, segment.contraction_limit.astype(q.dtype), axial)
    return energy + 0.5 * axial * elongation**2 + stop


def segment_strain_rate_energy(
    model: StrainModel,
    segment: Segment,
    q: Float[Array, " d"],
    qdot: Float[Array, " d"],
    quadrature_points: int,
    stiffness: tuple[Float[Array, " p"], Float[Array, " p"]] | None = None,
) -> Float[Array, ""]:
    """The elastic energy's quadratic form evaluated on the strain *rates* at ``(q, qdot)``.

    ``1/2 int (EI |du_bend/dt|^2 + GJ (du_twist/dt)^2) / L ds + 1/2 k_a (dL/dt)^2`` (stiffening
    at the current elongation), plus the non-strain coordinates' stiffness at zero (PAC's
    ``phi`` regulariser) on their rates. Times a damping time ``beta`` it is a Kelvin-Voigt
    material's dissipation function, ``1/2 qdot^T beta J(q)^T K J(q) qdot`` with ``J`` the strain
    Jacobian: it depends on the motion of the material, not on the coordinates. At the straight
    rest configuration it is ``1/2 qdot^T K_0 qdot``; away from it, the bending-plane angle of
    PCC/PAC is damped by the curvature it rotates (``|u| dphi/dt``), which ``K_0`` (where
    ``phi`` has no strain) leaves undamped.
    """
    elongation, elongation_rate = jax.jvp(model.elongation, (q,), (qdot,))
    nodes, weights, length, bending, torsion = _section_at(
        segment, quadrature_points, stiffness, elongation, q.dtype
    )
    _, strain_rate = jax.jvp(
        lambda x: jax.vmap(model.strain, in_axes=(None, 0))(x, nodes), (q,), (qdot,)
    )
    rate = _bending_torsion_energy(model, length, weights, bending, torsion, strain_rate)
    k_coord = segment.torsion_stiffness.astype(q.dtype) / length
    if model.coordinate_energy(q, k_coord) is not None:
        hess = jax.hessian(lambda x: model.coordinate_energy(x, k_coord))(jnp.zeros_like(q))
        rate = rate + jnp.matmul(
            jnp.matmul(0.5 * qdot, hess, precision=MATMUL_PRECISION),
            qdot,
            precision=MATMUL_PRECISION,
        )
    axial = segment.axial_stiffness.astype(q.dtype)
    return rate + 0.5 * axial * elongation_rate**2


#: Width of the contraction stop's contact band, as a fraction of the contraction limit.
STOP_BAND = 0.05


def contraction_stop_energy(
    elongation: Float[Array, ""], limit: Float[Array, ""], axial_stiffness: Float[Array, ""]
) -> Float[Array, ""]:
    """Energy (J) of a segment's end stop: zero until the contraction nears ``limit``.

    With ``w = STOP_BAND * limit`` and the depth ``x = (-dL - (limit - w)) / w`` into the contact
    band, the energy is ``k_a w^2 x^3 / (1 - x)`` for ``0 < x < 1``: it starts with zero value,
    force and stiffness (twice differentiable, so Newton steps see no kink), then grows without
    bound, ``+inf`` at and beyond the limit. No force, however large, contracts the segment past
    ``limit``; a solver step that would is rejected (its energy is not finite), and the
    equilibrium sits inside the band where the stop's force ``k_a w x^2 (3 - 2x) / (1 - x)^2``
    balances the load.
    """
    width = STOP_BAND * limit
    x = (-elongation - (limit - width)) / width
    inside = (x > 0) & (x < 1)
    xs = jnp.where(inside, x, 0.0)  # safe branch: exact zero value and derivatives outside
    energy = axial_stiffness * width**2 * xs**3 / (1.0 - xs)
    return jnp.where(x >= 1, jnp.inf, energy)


def _sum_over_segments(per_segment, robot: Robot, quadrature_points, stiffness, *arrays):
    """``sum_i per_segment(segment_i, arrays[.][i], stiffness_i)``: one ``vmap`` when the
    segments share a structure."""
    segments = robot.segments
    if stiffness is None:
        stiffness = robot_section_stiffness(robot, quadrature_points, arrays[0].dtype)
    structures = {
        (jtu.tree_structure(seg), tuple(jnp.shape(x) for x in jtu.tree_leaves(seg)))
        for seg in segments
    }
    if len(structures) == 1:
        stacked = jtu.tree_map(lambda *xs: jnp.stack(xs), *segments)
        return jnp.sum(jax.vmap(per_segment)(stacked, *arrays, stiffness))
    return sum(
        per_segment(seg, *(a[i] for a in arrays), (stiffness[0][i], stiffness[1][i]))
        for i, seg in enumerate(segments)
    )


def elastic_energy(
    model: StrainModel,
    robot: Robot,
    q: Float[Array, "n d"],
    quadrature_points: int,
    stiffness: tuple[Float[Array, "n p"], Float[Array, "n p"]] | None = None,
    rest: Float[Array, "n d"] | None = None,
) -> Float[Array, ""]:
    """Elastic energy (J) of all segments: one ``vmap`` when they share a structure.

    ``stiffness``: every segment's :func:`section_stiffness`, stacked, when already computed;
    ``rest``: every segment's rest coordinates (None: straight).
    """
    if rest is None:

        def one(seg, qi, k):
            return segment_elastic_energy(model, seg, qi, quadrature_points, k)

        return _sum_over_segments(one, robot, quadrature_points, stiffness, q)

    def one_from_rest(seg, qi, ri, k):
        return segment_elastic_energy(model, seg, qi, quadrature_points, k, ri)

    return _sum_over_segments(one_from_rest, robot, quadrature_points, stiffness, q, rest)


def strain_rate_energy(
    model: StrainModel,
    robot: Robot,
    q: Float[Array, "n d"],
    qdot: Float[Array, "n d"],
    quadrature_points: int,
    stiffness: tuple[Float[Array, "n p"], Float[Array, "n p"]] | None = None,
) -> Float[Array, ""]:
    """:func:`segment_strain_rate_energy` summed over the segments."""

    def one(seg, qi, vi, k):
        return segment_strain_rate_energy(model, seg, qi, vi, quadrature_points, k)

    return _sum_over_segments(one, robot, quadrature_points, stiffness, q, qdot)


def robot_section_stiffness(
    robot: Robot, quadrature_points: int, dtype
) -> tuple[Float[Array, "n p"], Float[Array, "n p"]]:
    """:func:`section_stiffness` of every segment, stacked."""
    per = [section_stiffness(seg, quadrature_points, dtype) for seg in robot.segments]
    return jnp.stack([b for b, _ in per]), jnp.stack([t for _, t in per])


def gravity_masses(
    robot: Robot, quadrature_points: int, dtype
) -> tuple[list[int], list[float], Float[Array, " p"]]:
    """Quadrature points ``(segment, s)`` along the body and the mass (kg) lumped at each.

    Mass is conserved: each node carries ``w_j rho A(s_j) L`` with the *rest* length ``L``, so a
    contracted segment is denser rather than lighter.
    """
    nodes, weights = gauss_legendre(quadrature_points)
    segs, ss, masses = [], [], []
    for i, seg in enumerate(robot.segments):
        density = seg.linear_density.astype(dtype) * jnp.ones(len(nodes), dtype)
        profile = seg.area_profile(jnp.asarray(nodes, dtype))
        if profile is not None:
            density = density * profile
        masses.append(jnp.asarray(weights, dtype) * density * seg.length.astype(dtype))
        segs.extend([i] * len(nodes))
        ss.extend(nodes.tolist())
    return segs, ss, jnp.concatenate(masses)


def moment_cotangent(
    moment_world: Float[Array, "3"], rotation: Float[Array, "3 3"]
) -> Float[Array, "3 3"]:
    """Cotangent on a frame's rotation whose VJP is the generalised force of a moment.

    Virtual work ``M . dtheta`` with ``[dtheta]x = dR R^T`` gives ``Q_j = 1/2 <dR/dq_j, [M]x R>``.
    """
    return jnp.matmul(0.5 * hat(moment_world), rotation, precision=MATMUL_PRECISION)


def mass_beyond(robot: Robot, s, dtype) -> Array:
    """``M_i(s) = int_s^1 rho A_i(v) L_i dv`` (kg): the mass of segment ``i`` beyond ``s``.

    The weight of a segment is ``-g . int_0^1 rho A L p(v) dv``; integrating by parts, with
    ``p' = (L + dL) R e_z``, it is ``-g . (M(0) p(0) + (L + dL) int_0^1 M(s) R(s) e_z ds)``, so
    the kinematics' own position nodes give it with no extra points. Mass uses the rest length
    ``L`` (a contracted segment is denser, not lighter). Exact for the polynomial density of a
    linear taper (4-point Gauss-Legendre on ``[s, 1]``).
    """
    nodes, weights = gauss_legendre(4)
    out = []
    for i, seg in enumerate(robot.segments):
        si = jnp.asarray(s[i], dtype)
        v = si[..., None] + (1.0 - si[..., None]) * jnp.asarray(nodes, dtype)
        density = seg.linear_density.astype(dtype) * jnp.ones_like(v)
        profile = seg.area_profile(v)
        if profile is not None:
            density = density * profile
        integral = jnp.sum(jnp.asarray(weights, dtype) * density, axis=-1)
        out.append((1.0 - si) * integral * seg.length.astype(dtype))
    return jnp.stack(out)
