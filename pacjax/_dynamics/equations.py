"""The equations of motion: the paper's full model (its eq. 7) as a vector field, its Jacobian
with the inertia held, and the weights its coordinates' errors take, for
:mod:`pacjax._dynamics.simulate`.

    M(q) qddot + C(q, qdot) qdot + G(q) + D qdot + K(q) = A(q) f_act + Q_ext(q)

- ``M`` and ``C qdot`` come from the kinetic energy of the body and point masses by automatic
  differentiation (:mod:`pacjax._model.inertia`); ``G + K`` is the gradient of the scene's potential
  energy without its tendons (elasticity, gravity, world-fixed forces); ``Q_ext`` the follower
  forces and point moments.
- ``D`` is Rayleigh damping (:class:`Damping`): ``alpha M(q) + beta K(q)``, with
  ``K(q) = J(q)^T K_s J(q)`` the elastic stiffness seen by the strain rates (``J`` the strain
  Jacobian, ``K_s`` the section stiffness): a Kelvin-Voigt material's damping, ``K_0`` at the
  straight rest configuration. Default: stiffness-proportional, with ``beta`` giving a 5 %
  damping ratio to the lowest mode of the straight, unloaded body.
- Tendons: ``A(q) f_act = -(dl/dq)^T tau`` with the motor PD law
  ``tau = max(kappa_P (l - l_bar) + kappa_D (l_dot - l_bar_dot), 0)``, ``l_bar = l_rest - u(t)``:
  the paper's ``f_act = kappa_D (l_bar_dot - l_dot) + kappa_P (l_bar - l)`` taken as the pull of
  the tendon, clipped at zero because a tendon cannot push. Clipping the sum (not gating it by
  ``l > l_bar``) keeps the force continuous in the state, which the implicit solver needs;
  at rest velocity it is exactly the statics' tension ``kappa_P max(l - l_bar, 0)``, so a
  damped motion settles on :func:`pacjax.solve_equilibrium`'s state. The default
  ``kappa_D = beta kappa_P`` damps the tendon springs like the body (stiffness-proportional).
  Tension-mode tendons pull with the commanded tension.
"""

import math
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
from jaxtyping import Array, Float

from .._config import MATMUL_PRECISION
from .._model.energy import strain_rate_energy
from .._model.hessian import energy_derivatives
from .._model.inertia import PHI_INERTIA_FACTOR, body_dynamics, kinetic_energy, mass_matrix
from .._model.inputs import as_traced_leaves, check_controls, check_q, solver_dtype
from .._model.kinematics import jacobian_and_value
from .._model.scene import Scene
from .damping import Damping, generalised_eigenvalues


class EquationsOfMotion(eqx.Module):
    """The scene's equations of motion under one damping: what the vector field needs, built
    once per simulation."""

    scene: Scene
    passive: Scene  # the scene without its tendons: their force is the motor law
    damping: Damping
    tendon_damping: Array | None
    phi_inertia: float = eqx.field(static=True)

    @staticmethod
    def build(scene: Scene, damping: Damping, phi_inertia: float, dtype) -> "EquationsOfMotion":
        passive = scene.replace(tendons=(), markers=())
        kd = damping.tendon_gains(scene, dtype) if scene.tendons else None
        return EquationsOfMotion(scene, passive, damping, kd, phi_inertia)

    def material_damping(self, q, qdot):
        """``K(q) qdot``: the gradient in ``qdot`` of the strain-rate energy."""
        scene = self.scene

        def rate_energy(v):
            return strain_rate_energy(
                scene.model,
                scene.robot,
                scene.coordinates(q),
                scene.coordinates(v),
                scene.quadrature_points,
            )

        return jax.grad(rate_energy)(qdot)

    def _length_mode(self, dtype):
        """Which tendons hold a commanded length (static), and their ``kappa_P`` (N/m; 1 for
        tension-mode tendons, whose gain is unused), as whole vectors: tendon by tendon, each
        tendon's slice and scatter would be a kernel of its own, in every derivative."""
        mask = np.array([t.mode == "length" for t in self.scene.tendons])
        gains = [t.gain if t.mode == "length" else jnp.ones(()) for t in self.scene.tendons]
        return mask, jnp.stack(gains).astype(dtype)

    def _motor_law(self, lengths, rates, u, udot):
        """Tendon tensions (N) under the motor PD law, and their derivative in the tendon
        rates (the derivative gain while the tendon is taut, zero when slack or in tension
        mode)."""
        mask, gain = self._length_mode(lengths.dtype)
        rest = self.scene.rest_tendon_lengths(lengths.dtype)
        pull = gain * (lengths - (rest - u)) + self.tendon_damping * (rates + udot)
        tension = jnp.where(mask, jnp.maximum(pull, 0.0), u)
        return tension, jnp.where(mask & (pull > 0), self.tendon_damping, 0.0)

    def tendon_forces(self, q, qdot, u, udot):
        """``A(q) f_act``: generalised forces of the tendons under the motor PD law."""
        lengths, lin = jax.linearize(self.scene.tendon_lengths, q)
        tension, _ = self._motor_law(lengths, lin(qdot), u, udot)
        (force,) = jax.linear_transpose(lin, q)(-tension)
        return force

    def forces(self, q, qdot, u, udot, mass):
        """Every generalised force but inertia's: ``-G - K - D qdot + A f_act + Q_ext``, the
        mass-proportional damping on ``mass`` (``M(q)``, passed in to be computed once).

        The motors pull as the statics' tendon springs do under :meth:`_spring_controls`, so
        ``-G - K + A f_act`` is minus one gradient of the scene's potential energy, tendons
        included, at those controls: one reverse pass through the kinematics instead of two
        (the passive potential's and the tendon lengths' transpose), after one forward
        derivative for the tendon rates. :meth:`tendon_forces` is the motor law written out."""
        springs = u
        if self.scene.tendons:
            rates = jax.jvp(self.scene.tendon_lengths, (q,), (qdot,))[1]
            springs = self._spring_controls(rates, u, udot)
        force = -jax.grad(self.scene.potential_energy)(q, springs)
        extra = self.passive.nonconservative_forces(q)
        if extra is not None:
            force = force + extra
        force = force - self.damping.stiffness * self.material_damping(q, qdot)
        return force - self.damping.mass * jnp.matmul(mass, qdot, precision=MATMUL_PRECISION)

    def accelerations(self, q, qdot, u, udot):
        """``qddot`` from ``M qddot = -C qdot - G - K - D qdot + A f_act + Q_ext``."""
        mass, bias = body_dynamics(self.scene, q, qdot, self.phi_inertia)
        operator = lx.MatrixLinearOperator(mass, lx.positive_semidefinite_tag)
        # throw=False: a wild Newton iterate of the implicit solver gives NaN here, and diffrax
        # must see it to reject the step (a raise would abort the whole simulation).
        force = self.forces(q, qdot, u, udot, mass) - bias
        return lx.linear_solve(operator, force, lx.Cholesky(), throw=False).value

    def stiff_jacobian(self, q, qdot, u, udot) -> Float[Array, "2n 2n"]:
        """``d(qdot, qddot) / d(q, qdot)`` with the inertia frozen, for a W-method
        (:class:`pacjax._dynamics.rosenbrock.Rosenbrock23`, whose order does not depend on it).

        ``qddot``'s rows are ``M(q)^-1 (dF/dq, dF/dqdot)`` with ``M`` held fixed and the Coriolis
        forces left out: the derivatives of every other force but two slow terms (below).

        - ``dF/dq``: minus the Hessian of the potential energy (structured,
          :func:`pacjax._model.hessian.energy_derivatives`) with each taut tendon a spring that
          pulls as its motor does now, derivative gain included (:meth:`_spring_controls`):
          the tendons' geometric stiffness is that of their whole tension, not of its static
          part; then the material damping's derivative in ``q`` and the follower loads'.
          The motors' damping tension is large while the tendons move, and it bends the body
          through the tendons' curvature: without its share the steps after a step command
          were several times shorter.
        - ``dF/dqdot``: the damping: material, mass-proportional, and the motors' derivative
          gains on taut tendons.

        Left out: the mass-proportional damping's derivative in ``q``, the motors' damping
        through the change of the tendons' Jacobian (``J^T kappa_D (dJ/dq qdot)``), and the
        inertial forces' derivatives (``d(M a + C qdot)``: the kinematics' third derivatives).
        The last matter where PAC's plane angle swings round a segment passing near straight:
        with them the steps were several times fewer, but each Jacobian several times dearer,
        and the simulation slower on CPU (``benchmarks/RESULTS.md`` has the counts and times).
        """
        n = q.shape[0]
        scene = self.scene
        mass = mass_matrix(scene, q, self.phi_inertia)
        d_qdot = -self.damping.stiffness * jax.jacfwd(self.material_damping, argnums=1)(q, qdot)
        d_qdot = d_qdot - self.damping.mass * mass
        springs = u
        if scene.tendons:
            jac, lengths = jacobian_and_value(scene.tendon_lengths, q)
            rates = jnp.matmul(jac, qdot, precision=MATMUL_PRECISION)
            _, gains = self._motor_law(lengths, rates, u, udot)
            d_qdot = d_qdot - jnp.matmul(jac.T * gains, jac, precision=MATMUL_PRECISION)
            springs = self._spring_controls(rates, u, udot)
        _, _, hessian = energy_derivatives(scene, q, springs)
        d_q = -hessian - self.damping.stiffness * jax.jacfwd(self.material_damping)(q, qdot)
        if not self.passive.is_conservative:
            d_q = d_q + jax.jacfwd(self.passive.nonconservative_forces)(q)
        factor = jax.scipy.linalg.cho_factor(mass)
        lower = jax.scipy.linalg.cho_solve(factor, jnp.concatenate([d_q, d_qdot], axis=1))
        upper = jnp.concatenate([jnp.zeros((n, n), q.dtype), jnp.eye(n, dtype=q.dtype)], axis=1)
        return jnp.concatenate([upper, lower], axis=0)

    def _spring_controls(self, rates, u, udot):
        """Controls under which the statics' tendon springs pull as the motors do at tendon
        rates ``rates``: ``kappa_P (l - l_bar') = kappa_P (l - l_bar) + kappa_D (l_dot +
        l_bar_dot)``, i.e. ``u' = u + kappa_D / kappa_P (l_dot + u_dot)`` in length mode (the
        gain is positive there); tension mode pulls with ``u`` already."""
        mask, gain = self._length_mode(u.dtype)
        return u + jnp.where(mask, self.tendon_damping / gain, 0.0) * (rates + udot)


def control_fn(controls, n_tendons: int, dtype) -> Callable:
    """``t -> (u, du/dt)`` for constant or callable controls."""
    if controls is None:
        zero = jnp.zeros(n_tendons, dtype)
        return lambda t: (zero, zero)
    if callable(controls):

        def fn(t):
            u, udot = jax.jvp(lambda x: jnp.asarray(controls(x), dtype), (t,), (jnp.ones_like(t),))
            return u, udot

        return fn
    return lambda t: (controls, jnp.zeros_like(controls))


# ------------------------------------------------------------------------------ public helpers
def accelerations(
    scene: Scene,
    q,
    qdot,
    controls=None,
    controls_rate=None,
    damping: Damping | None = None,
    phi_inertia: float = PHI_INERTIA_FACTOR,
) -> Float[Array, " n_dofs"]:
    """``qddot`` of the full model at ``(q, qdot)`` under ``controls`` changing at
    ``controls_rate`` (per second). ``damping`` None: no damping."""
    q = jnp.asarray(q)
    dtype = q.dtype
    u = scene.default_controls(dtype) if controls is None else jnp.asarray(controls, dtype)
    udot = jnp.zeros_like(u) if controls_rate is None else jnp.asarray(controls_rate, dtype)
    model = EquationsOfMotion.build(
        scene, Damping() if damping is None else damping, phi_inertia, dtype
    )
    return model.accelerations(q, jnp.asarray(qdot, dtype), u, udot)


def total_energy(
    scene: Scene, q, qdot, controls=None, phi_inertia: float = PHI_INERTIA_FACTOR
) -> Float[Array, ""]:
    """Kinetic plus potential energy (J), tendons included with their static (spring) energy.

    Conserved by undamped motions under constant controls (with ``kappa_D = 0``) when every
    load is conservative.
    """
    q = jnp.asarray(q)
    u = scene.default_controls(q.dtype) if controls is None else jnp.asarray(controls, q.dtype)
    return kinetic_energy(scene, q, jnp.asarray(qdot, q.dtype), phi_inertia) + (
        scene.potential_energy(q, u)
    )


def natural_frequencies(
    scene: Scene, q=None, controls=None, phi_inertia: float = PHI_INERTIA_FACTOR
) -> Float[Array, " n_dofs"]:
    """Undamped natural frequencies (Hz, ascending) of small motions about ``q``.

    Eigenvalues of ``M^-1 K``, ``K`` the Hessian of the potential energy (tendons as springs)
    at ``q`` (an equilibrium, e.g. ``solve_equilibrium(...).q``; default straight). A negative
    eigenvalue (an unstable equilibrium) gives a NaN frequency. Conservative scenes only.
    """
    if not scene.is_conservative:
        raise ValueError(
            "natural_frequencies needs a conservative scene (no follower force or moment)"
        )
    dtype = solver_dtype(scene)
    q = check_q(scene, q, dtype)
    u = check_controls(scene, controls, dtype)
    return _frequencies(as_traced_leaves(scene, dtype), q, u, phi_inertia)


@eqx.filter_jit
def _frequencies(scene, q, u, phi_inertia):
    stiffness = jax.hessian(scene.potential_energy)(q, u)
    eig = generalised_eigenvalues(stiffness, mass_matrix(scene, q, phi_inertia))
    return jnp.sqrt(jnp.where(eig >= 0, eig, jnp.nan)) / (2 * math.pi)


def vector_field(t, y, args):
    """``(qdot, qddot)``. A function of its arguments only (the model and controls come in
    ``args``, not by closure): its trace, and the traces of its derivatives, are made once and
    reused everywhere the solver calls or differentiates it."""
    model, controls = args
    q, qdot = y
    u, udot = control_fn(controls, model.scene.n_tendons, q.dtype)(t)
    return qdot, model.accelerations(q, qdot, u, udot)


def vector_field_jacobian(t, y, args):
    """:meth:`EquationsOfMotion.stiff_jacobian` along the flattened state ``(q, qdot)``."""
    model, controls = args
    q, qdot = y
    u, udot = control_fn(controls, model.scene.n_tendons, q.dtype)(t)
    return model.stiff_jacobian(q, qdot, u, udot)


def plane_angle_weights(y, args):
    """Weights on the error of each coordinate and velocity (a pytree like ``y = (q, qdot)``):
    one, but on PCC/PAC's free plane angle ``phi`` the segment's bend ``theta`` (rad, up to 1).

    Turning the bending plane by ``dphi`` moves a segment bent by ``theta`` by about
    ``theta dphi`` of its length (``dphi`` of it once ``theta`` passes a radian): the error in
    ``phi`` (and in its rate) moves the body in proportion to ``theta``. Near straight the
    polar coordinates swing ``phi`` round fast while the body barely moves; measured as it
    moves the body, that swing no longer sets the step size. ``theta`` is the larger of the
    bending angles at the middle and the end of the segment (an S-shaped PAC segment bends at
    its middle with none at its end).
    """
    model, _ = args
    scene = model.scene
    q, _ = y
    weights = jnp.ones_like(q)
    k = scene.model.free_plane_angle()
    if k is None:
        return weights, weights
    coords = scene.coordinates(q)
    lengths = scene.robot.stacked("length").astype(q.dtype)
    s = lengths[:, None] * jnp.asarray([0.5, 1.0], q.dtype)
    basis = scene.model.plane_angle_basis(s)  # (segments, 2, k)
    bends = jnp.einsum("nk,npk->np", coords[:, :k], basis, precision=MATMUL_PRECISION)
    theta = jnp.max(jnp.abs(bends), axis=1)
    full = jnp.ones_like(coords).at[:, k].set(jnp.minimum(theta, 1.0))
    weights = scene.free_part(full)
    return weights, weights
