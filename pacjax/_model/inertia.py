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

- the mass matrix ``M(q) = J_v^T m J_v + J_w^T I J_w`` from the Jacobians of the node
  positions and angular velocities (one ``linearize`` of the kinematics, all directions at
  once); it equals the Hessian of ``T`` in ``qdot`` (checked in the tests);
- the Coriolis/centrifugal force ``C(q, qdot) qdot = d/dt(dT/dqdot) - dT/dq`` at zero
  acceleration, straight from Lagrange's equations with ``jvp``/``grad``
  (:func:`coriolis_forces`, the reference), or in forward mode only from second directional
  derivatives of the kinematics (:func:`body_dynamics`, what the simulator uses: it compiles
  several times faster, and the implicit solver differentiates it once more). No Christoffel
  symbols are written by hand; the two agree to round-off (tested).

PCC's and PAC's bending-plane angle ``phi`` moves no mass when its segment is straight, so
``M`` is singular there (the same polar singularity as the Hessian of the elastic energy). A
regularising inertia ``phi_inertia * m_i L_i^2 / 12`` (the segment's transverse moment of
inertia about its middle, times a small factor, default 1e-6 like the stiffness regulariser on
``phi``) is added on each ``phi``: with the default regulariser on the stiffness the ``phi``
mode then has a frequency of the order of the first bending mode, so it adds no stiff time scale,
and its relative effect on a bent segment is of the order of the factor.
"""

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import MATMUL_PRECISION
from .loads import PointMass
from .quadrature import gauss_legendre
from .robot import known_sites
from .scene import Scene
from .strain import PlanarCurvature

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
    return body_dynamics(scene, q, jnp.zeros_like(q), phi_inertia)[0]


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

        def velocities(x, kinematics=kinematics):
            (rot, _), (rot_dot, vel) = jax.jvp(kinematics, (x,), (qdot,))
            return vel, _vee_skew(
                jnp.matmul(jnp.swapaxes(rot, -1, -2), rot_dot, precision=MATMUL_PRECISION)
            )

        (_, omega), (acc, alpha) = jax.jvp(velocities, (q,), (qdot,))
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
