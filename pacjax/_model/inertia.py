"""Inertia: kinetic energy, mass matrix and Coriolis/centrifugal forces, by autodiff.

The body is lumped at the scene's Gauss-Legendre nodes (node mass ``w_j rho A(s_j) L`` with the
*rest* length ``L``, so mass is conserved under contraction, as for the weight), plus the
scene's :class:`~pacjax.PointMass` es. Each node is a thin slice of a solid round section of
radius ``r(s)``: besides its translation it spins with the body angular velocity
``omega = vee(R^T dR/dt)``, with principal moments of inertia ``m r^2 / 4`` about the
cross-section axes x, y and ``m r^2 / 2`` about the backbone (rotary inertia of a Rayleigh
beam). Point masses have no rotational inertia. The kinetic energy

    T(q, qdot) = 1/2 sum_k m_k |v_k|^2 + 1/2 sum_k omega_k^T I_k omega_k

is evaluated with one forward-mode derivative of the kinematics (``v, dR/dt = jvp``). From it:

- the mass matrix ``M(q) = J_v^T m J_v + J_w^T I J_w`` from the Jacobians of the mass points'
  velocities and angular velocities; it equals the Hessian of ``T`` in ``qdot`` (checked in the
  tests);
- the Coriolis/centrifugal force ``C(q, qdot) qdot = J_v^T m a_0 + J_w^T (I alpha_0 + omega x
  I omega)``, with ``a_0``, ``alpha_0`` the accelerations at zero ``qddot``. No Christoffel
  symbols are written by hand.

What the simulator uses (:func:`body_dynamics`) takes the Jacobians from the segments'
structure, as the statics' Hessian does: segment ``j``'s coordinates move its own points
through its local kinematics and everything beyond its end rigidly, so each segment's
kinematics is differentiated along its own coordinates only (:func:`structured_body_dynamics`);
the accelerations at zero ``qddot`` are the frames' second derivative along ``qdot``, two nested
``jvp`` of the chained kinematics, in both. Two references check it: ``M`` and ``C qdot`` by
forward derivatives of the whole chained kinematics (:func:`chained_body_dynamics`, also the
path for mass points at sites known only at run time), and Lagrange's equations
``d/dt(dT/dqdot) - dT/dq`` by ``jvp``/``grad`` (:func:`coriolis_forces`); all agree to
round-off (tested).

PCC's and PAC's bending-plane angle ``phi`` moves no mass when its segment is straight, so
``M`` is singular there (the same polar singularity as the Hessian of the elastic energy). A
regularising inertia ``phi_inertia * m_i L_i^2 / 12`` (the segment's transverse moment of
inertia about its middle, times a small factor, default 1e-6 like the stiffness regulariser on
``phi``) is added on each ``phi``: with the default regulariser on the stiffness the ``phi``
mode then has a frequency of the order of the first bending mode, so it adds no stiff time scale,
and its relative effect on a bent segment is of the order of the factor.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import MATMUL_PRECISION
from .kinematics import Knots, chain_segments
from .loads import PointMass
from .quadrature import gauss_legendre
from .rotation import cross3, matmul3, matvec3
from .scene import Scene
from .strain import PlanarCurvature
from .values import known_sites

#: Default factor of the regularising inertia on PCC/PAC's bending-plane angle ``phi``.
PHI_INERTIA_FACTOR = 1e-6

# Principal moments of inertia of a thin solid disc of unit mass and unit radius.
_DISC = np.array([0.25, 0.25, 0.5])


def _body_nodes(scene: Scene, dtype):
    """Gauss-Legendre nodes of every segment: static ``(segments, s)``, masses (kg) and
    gyration radii (m: the radius of the solid disc with the section's moments) as arrays."""
    nodes, weights = gauss_legendre(scene.quadrature_points)
    segs, masses, radii = [], [], []
    for i, seg in enumerate(scene.robot.segments):
        s = jnp.asarray(nodes, dtype)
        density = seg.linear_density.astype(dtype) * jnp.ones_like(s)
        profile = seg.area_profile(s)
        if profile is not None:
            density = density * profile
        masses.append(jnp.asarray(weights, dtype) * density * seg.length.astype(dtype))
        # A hollow disc's moments per unit mass are a solid one's of radius^2 = r_o^2 + r_i^2.
        radii.append(jnp.hypot(seg.radius_at(s), seg.inner_radius_at(s)).astype(dtype))
        segs += [i] * len(nodes)
    s_all = np.tile(nodes, scene.n_segments)
    return np.asarray(segs), s_all, jnp.concatenate(masses), jnp.concatenate(radii)


def inertia_sites(scene: Scene, dtype) -> list:
    """Mass points of the body as groups ``(segments, s, masses (p,), moments (p, 3) | None)``.

    ``segments`` is static; ``s`` a numpy array for the body's nodes (the kinematics' fast path
    for known points) and the traced sites of point masses. Principal moments of inertia in
    kg m^2 about the local cross-section axes (x, y, backbone); None for point masses.
    """
    segs, s, masses, radius = _body_nodes(scene, dtype)
    moments = masses[:, None] * radius[:, None] ** 2 * jnp.asarray(_DISC, dtype)
    point_masses = scene.loads_of(PointMass)
    if not point_masses:
        return [(segs, s, masses, moments)]
    pm_segs = np.asarray([pm.segment for pm in point_masses])
    pm_s = known_sites([pm.s for pm in point_masses], dtype)
    pm_masses = jnp.stack([pm.mass for pm in point_masses]).astype(dtype)
    if isinstance(pm_s, np.ndarray):
        # Known sites join the body's nodes: one kinematics pass for all of them (a point mass
        # has no rotational inertia).
        return [
            (
                np.concatenate([segs, pm_segs]),
                np.concatenate([s, pm_s]),
                jnp.concatenate([masses, pm_masses]),
                jnp.concatenate([moments, jnp.zeros((len(point_masses), 3), dtype)]),
            )
        ]
    return [(segs, s, masses, moments), (pm_segs, pm_s, pm_masses, None)]


def coordinate_inertia(
    scene: Scene, dtype, phi_inertia: float = PHI_INERTIA_FACTOR
) -> Float[Array, " n_dofs"] | None:
    """Diagonal regularising inertia (kg m^2) on PCC/PAC's ``phi``, None for other models."""
    if not isinstance(scene.model, PlanarCurvature) or phi_inertia == 0:
        return None
    d = scene.dofs_per_segment
    lengths = scene.robot.stacked("length").astype(dtype)
    _, _, masses, _ = _body_nodes(scene, dtype)
    seg_mass = masses.reshape(scene.n_segments, -1).sum(axis=1)
    diag = jnp.zeros((scene.n_segments, d), dtype)
    diag = diag.at[:, d - 2].set(phi_inertia * seg_mass * lengths**2 / 12.0)
    return scene.free_part(diag)


def _vee_skew(a: Float[Array, "*b 3 3"]) -> Float[Array, "*b 3"]:
    """The vector of the skew-symmetric part of ``a``."""
    return 0.5 * jnp.stack(
        [a[..., 2, 1] - a[..., 1, 2], a[..., 0, 2] - a[..., 2, 0], a[..., 1, 0] - a[..., 0, 1]],
        axis=-1,
    )


def kinetic_energy(
    scene: Scene,
    q: Float[Array, " n_dofs"],
    qdot: Float[Array, " n_dofs"],
    phi_inertia: float = PHI_INERTIA_FACTOR,
) -> Float[Array, ""]:
    """Kinetic energy (J) of the body and point masses at ``(q, qdot)``."""
    dtype = q.dtype
    energy = jnp.zeros((), dtype)
    for segs, s, masses, moments in inertia_sites(scene, dtype):
        (rot, _), (rot_dot, vel) = jax.jvp(
            lambda x, g=segs, v=s: scene.frames(x, g, v), (q,), (qdot,)
        )
        energy = energy + 0.5 * jnp.sum(masses * jnp.sum(vel * vel, axis=-1))
        if moments is not None:
            omega = _vee_skew(
                jnp.matmul(jnp.swapaxes(rot, -1, -2), rot_dot, precision=MATMUL_PRECISION)
            )
            energy = energy + 0.5 * jnp.sum(moments * omega * omega)
    extra = coordinate_inertia(scene, dtype, phi_inertia)
    if extra is not None:
        energy = energy + 0.5 * jnp.sum(extra * qdot * qdot)
    return energy


def mass_matrix(
    scene: Scene, q: Float[Array, " n_dofs"], phi_inertia: float = PHI_INERTIA_FACTOR
) -> Float[Array, "n_dofs n_dofs"]:
    """Generalised mass matrix ``M(q)`` (SI units of each coordinate pair), symmetric."""
    groups = inertia_sites(scene, q.dtype)
    if len(groups) > 1:
        return chained_body_dynamics(scene, q, jnp.zeros_like(q), phi_inertia)[0]
    lumped = _knot_masses(scene, q.dtype)
    jac_pos, jac_ang = _knot_jacobians(scene, q, lumped.knots)
    return _mass_from_jacobians(scene, jac_pos, jac_ang, lumped.masses, lumped.moments, phi_inertia)


def coriolis_forces(
    scene: Scene,
    q: Float[Array, " n_dofs"],
    qdot: Float[Array, " n_dofs"],
    phi_inertia: float = PHI_INERTIA_FACTOR,
) -> Float[Array, " n_dofs"]:
    """Coriolis and centrifugal forces ``C(q, qdot) qdot`` (generalised forces), from the
    Lagrangian: ``d/dt(dT/dqdot) - dT/dq`` at zero acceleration, the rate of the momentum
    ``dT/dqdot`` taken with a ``jvp`` in ``q`` along ``qdot``.

    A reference implementation (reverse mode inside forward mode: slow to compile);
    :func:`body_dynamics` computes the same forces in forward mode only.
    """

    def energy(x, v):
        return kinetic_energy(scene, x, v, phi_inertia)

    def momentum(x):
        return jax.grad(energy, argnums=1)(x, qdot)

    _, momentum_rate = jax.jvp(momentum, (q,), (qdot,))
    return momentum_rate - jax.grad(energy, argnums=0)(q, qdot)


def body_dynamics(
    scene: Scene,
    q: Float[Array, " n_dofs"],
    qdot: Float[Array, " n_dofs"],
    phi_inertia: float = PHI_INERTIA_FACTOR,
) -> tuple[Float[Array, "n_dofs n_dofs"], Float[Array, " n_dofs"]]:
    """Mass matrix ``M(q)`` and Coriolis/centrifugal forces ``C(q, qdot) qdot``: from the
    segments' structure (:func:`structured_body_dynamics`) when every mass point's site is
    known at trace time, else by forward derivatives of the whole kinematics
    (:func:`chained_body_dynamics`)."""
    groups = inertia_sites(scene, q.dtype)
    if len(groups) == 1:
        return structured_body_dynamics(scene, q, qdot, phi_inertia)
    return chained_body_dynamics(scene, q, qdot, phi_inertia)


def chained_body_dynamics(
    scene: Scene,
    q: Float[Array, " n_dofs"],
    qdot: Float[Array, " n_dofs"],
    phi_inertia: float = PHI_INERTIA_FACTOR,
) -> tuple[Float[Array, "n_dofs n_dofs"], Float[Array, " n_dofs"]]:
    """Mass matrix and Coriolis/centrifugal forces in one kinematics pass, forward mode only.

    With ``J_v``, ``J_w`` the Jacobians of the site velocities and body angular velocities
    (one ``linearize``), Lagrange's equations of the lumped body give

        M = J_v^T m J_v + J_w^T I J_w,
        C qdot = J_v^T m a_0 + J_w^T (I alpha_0 + omega x I omega),

    where ``a_0`` and ``alpha_0`` are the site accelerations at zero ``qddot`` (second
    directional derivatives of the kinematics along ``qdot``, nested ``jvp``) and the last term
    is Euler's for a spinning section. Equal to :func:`coriolis_forces` (tested).
    """
    dtype = q.dtype
    n = q.shape[0]
    mat = jnp.zeros((n, n), dtype)
    bias = jnp.zeros(n, dtype)
    for segs, s, masses, moments in inertia_sites(scene, dtype):

        def kinematics(x, segs=segs, s=s):
            return scene.frames(x, segs, s)

        omega, acc, alpha = _site_accelerations(kinematics, q, qdot)
        (rot, _), lin = jax.linearize(kinematics, q)
        d_rot, d_pos = jax.vmap(lin)(jnp.eye(n, dtype=dtype))  # (n, p, 3, 3), (n, p, 3)
        mat = mat + jnp.einsum("ipa,p,jpa->ij", d_pos, masses, d_pos, precision=MATMUL_PRECISION)
        bias = bias + jnp.einsum("ipa,p,pa->i", d_pos, masses, acc, precision=MATMUL_PRECISION)
        if moments is not None:
            d_omega = _vee_skew(
                jnp.matmul(jnp.swapaxes(rot, -1, -2)[None], d_rot, precision=MATMUL_PRECISION)
            )  # (n, p, 3)
            mat = mat + jnp.einsum(
                "ipa,pa,jpa->ij", d_omega, moments, d_omega, precision=MATMUL_PRECISION
            )
            euler = moments * alpha + jnp.cross(omega, moments * omega)
            bias = bias + jnp.einsum("ipa,pa->i", d_omega, euler, precision=MATMUL_PRECISION)
    extra = coordinate_inertia(scene, dtype, phi_inertia)
    if extra is not None:
        mat = mat + jnp.diag(extra)
    return 0.5 * (mat + mat.T), bias


def _site_accelerations(frames, q, qdot):
    """Body angular velocities ``omega`` of the points whose world frames are ``frames(q)``
    (rotations, positions) and their world and angular accelerations at zero ``qddot``
    (``a_0 = (dJ/dq qdot) qdot``, ``alpha_0``): the second directional derivative of their
    frames along ``qdot`` (nested ``jvp``)."""

    def velocities(x):
        (rot, _), (rot_dot, vel) = jax.jvp(frames, (x,), (qdot,))
        return vel, _vee_skew(
            jnp.matmul(jnp.swapaxes(rot, -1, -2), rot_dot, precision=MATMUL_PRECISION)
        )

    (_, omega), (acc, alpha) = jax.jvp(velocities, (q,), (qdot,))
    return omega, acc, alpha


class _SegmentFrames(NamedTuple):
    """Every segment's frames at its knots, local (in its base frame) with their derivatives
    along its own coordinates, and in the world."""

    rot: Array  # (n, k, 3, 3) local rotations
    d_rot: Array  # (n, k, 3, 3, d)
    d_pos: Array  # (n, k, 3, d)
    base_rot: Array  # (n, 3, 3) world rotation of each segment's base
    world_rot: Array  # (n, k, 3, 3)
    world_pos: Array  # (n, k, 3)


def _segment_frames(scene: Scene, q: Float[Array, " n_dofs"], knots: Knots) -> _SegmentFrames:
    dtype = q.dtype
    lengths = scene.robot.stacked("length").astype(dtype)
    grid = jnp.asarray(knots.s, dtype)
    (d_rot, d_pos, _), (rot, pos, _) = jax.vmap(
        lambda qi, li, ki: scene.segment_frames_jacobian(qi, li, ki, None)
    )(scene.coordinates(q), lengths, grid)
    base_rot, base_pos = chain_segments(
        rot[:, -1], pos[:, -1], scene.robot.base_rotation, scene.robot.base_position
    )
    world_rot = matmul3(base_rot[:, None], rot)
    world_pos = base_pos[:, None] + matvec3(base_rot[:, None], pos)
    return _SegmentFrames(rot, d_rot, d_pos, base_rot, world_rot, world_pos)


def _knot_jacobians(
    scene: Scene, q: Float[Array, " n_dofs"], knots: Knots
) -> tuple[Float[Array, "k n_dofs 3"], Float[Array, "k n_dofs 3"]]:
    """Jacobians along ``q`` of the world velocities and body angular velocities of the frames
    at every knot (segment by segment, flattened), from each segment's local Jacobian.

    Segment ``j``'s coordinates move its own points through its local kinematics, and
    every point beyond its end rigidly, with the twist its end frame gets: a point ``x`` of
    a later segment moves by ``w x (x - e_j) + t`` (``w``, ``t`` the end frame's angular and
    linear motion in the world, ``e_j`` its position) and turns with ``w``. Each segment's
    kinematics is differentiated along its own ``d`` coordinates only
    (:meth:`Scene.segment_frames_jacobian`, point by point along the bending angles for
    PCC/PAC), not along all of the robot's as a Jacobian of the chained kinematics is.
    """
    f = _segment_frames(scene, q, knots)
    n, _, _, d = f.d_pos.shape
    dtype = q.dtype
    mm = MATMUL_PRECISION
    # Own segment: the local derivatives, turned into the world (positions) or read in the
    # point's own frame (angular velocities: vee(R^T dR)).
    own_pos = jnp.einsum("iab,ipbk->ipka", f.base_rot, f.d_pos, precision=mm)
    own_ang = _vee_skew(jnp.einsum("ipba,ipbck->ipkac", f.rot, f.d_rot, precision=mm))
    # Beyond segment j's end: the end frame's twist in the world, vee(dE E^T) turned.
    end_ang = _vee_skew(jnp.einsum("jabk,jcb->jkac", f.d_rot[:, -1], f.rot[:, -1], precision=mm))
    end_ang = jnp.einsum("jab,jkb->jka", f.base_rot, end_ang, precision=mm)  # (n, d, 3)
    end_lin = own_pos[:, -1]  # (n, d, 3)
    lever = f.world_pos[:, :, None, :] - f.world_pos[None, None, :, -1, :]  # (i, p, j, 3)
    far_pos = (
        jnp.stack(
            cross3(
                tuple(end_ang[None, None, :, :, a] for a in range(3)),
                tuple(lever[:, :, :, None, a] for a in range(3)),
            ),
            axis=-1,
        )
        + end_lin[None, None]
    )  # (i, p, j, k, 3)
    far_ang = jnp.einsum("ipba,jkb->ipjka", f.world_rot, end_ang, precision=mm)
    rows = np.arange(n)
    beyond = jnp.asarray(rows[:, None] > rows[None, :], dtype)[:, None, :, None, None]
    same = jnp.asarray(np.eye(n), dtype)[:, None, :, None, None]
    jac_pos = beyond * far_pos + same * own_pos[:, :, None]
    jac_ang = beyond * far_ang + same * own_ang[:, :, None]
    free = scene.free_coordinates()

    def flat(jac):
        jac = jac.reshape(-1, n * d, 3)
        return jac if free is None else jac[:, free]

    return flat(jac_pos), flat(jac_ang)


class _KnotMasses(NamedTuple):
    """The mass points with known sites, lumped on the knots that hold them. The inertia is
    summed over every knot (zero where none lies) rather than over points picked out of the
    knot grid: :meth:`Knots.select` takes a static slice per run of points and per derivative,
    each a kernel of its own on XLA:CPU, where the knots without mass only add arithmetic to
    kernels that run anyway."""

    knots: Knots
    masses: Array  # (k,) kg at each knot, segment by segment
    moments: Array  # (k, 3) principal moments of inertia (kg m^2) in the knot's frame


def _knot_masses(scene: Scene, dtype) -> _KnotMasses:
    ((segs, s, masses, moments),) = inertia_sites(scene, dtype)
    knots = Knots(scene.n_segments, segs, s, scene.kinematics)
    size = knots.s.size
    # Points at one knot (a segment's end mass and a payload there) add up.
    return _KnotMasses(
        knots,
        jnp.zeros(size, dtype).at[knots.flat_index].add(masses),
        jnp.zeros((size, 3), dtype).at[knots.flat_index].add(moments),
    )


def _knot_world_frames(scene: Scene, knots: Knots):
    """``q -> (rotations (k, 3, 3), positions (k, 3))`` of the world frames at every knot."""

    def frames(q):
        rot, pos = scene.knot_grid_frames(q, knots)
        return rot.reshape(-1, 3, 3), pos.reshape(-1, 3)

    return frames


def structured_body_dynamics(
    scene: Scene,
    q: Float[Array, " n_dofs"],
    qdot: Float[Array, " n_dofs"],
    phi_inertia: float = PHI_INERTIA_FACTOR,
) -> tuple[Float[Array, "n_dofs n_dofs"], Float[Array, " n_dofs"]]:
    """:func:`chained_body_dynamics`' ``M`` and ``C qdot`` from the segments' local
    Jacobians (:func:`_knot_jacobians`), for mass points whose sites are all known."""
    lumped = _knot_masses(scene, q.dtype)
    jac_pos, jac_ang = _knot_jacobians(scene, q, lumped.knots)
    # The accelerations by forward derivatives of the frames alone: a derivative of the
    # segments' local Jacobians along qdot would carry the kinematics' third derivatives.
    frames = _knot_world_frames(scene, lumped.knots)
    omega, acc, alpha = _site_accelerations(frames, q, qdot)
    mm = MATMUL_PRECISION
    masses, moments = lumped.masses, lumped.moments
    euler = moments * alpha + jnp.cross(omega, moments * omega)
    bias = jnp.einsum("pia,p,pa->i", jac_pos, masses, acc, precision=mm)
    bias = bias + jnp.einsum("pia,pa->i", jac_ang, euler, precision=mm)
    return _mass_from_jacobians(scene, jac_pos, jac_ang, masses, moments, phi_inertia), bias


def _mass_from_jacobians(scene: Scene, jac_pos, jac_ang, masses, moments, phi_inertia: float):
    """``J_v^T m J_v + J_w^T I J_w`` plus the regularising inertia on ``phi``, symmetric."""
    mm = MATMUL_PRECISION
    mat = jnp.einsum("pia,p,pja->ij", jac_pos, masses, jac_pos, precision=mm)
    mat = mat + jnp.einsum("pia,pa,pja->ij", jac_ang, moments, jac_ang, precision=mm)
    extra = coordinate_inertia(scene, jac_pos.dtype, phi_inertia)
    if extra is not None:
        mat = mat + jnp.diag(extra)
    return 0.5 * (mat + mat.T)
