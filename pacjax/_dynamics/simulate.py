"""Dynamics: the paper's full model (its eq. 7), integrated with diffrax.

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

The state ``(q, qdot)`` is integrated with adaptive steps (PID controller) by a stiff solver:
the tendon springs, the axial stiffness and the stiffness-proportional damping are fast against
the soft body's motion. At moderate tolerances (``rtol >= 1e-5``) the default is
:class:`pacjax._dynamics.rosenbrock.Rosenbrock23`, a linearly implicit W-method, with the
frozen-inertia Jacobian (:meth:`_Model.frozen_inertia_jacobian`): the potential's Hessian and
the damping, without the inertia's derivatives, which are slow and the dearest part of an exact
Jacobian. At tight ones it is ``diffrax.Kvaerno5`` (L-stable, 5th order), whose stage equations
are solved by diffrax's chord method with the Jacobian taken in forward mode
(:class:`pacjax._chord.DenseChord`). The vector field is jitted on its own, so that its trace and
its derivatives' are made once. Gradients of a trajectory with respect to any scene or damping
parameter, the initial state or the controls go through diffrax's checkpointed adjoint.
"""

import math
from collections.abc import Callable

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .. import _deprecated
from .._chord import kvaerno5
from .._config import MATMUL_PRECISION
from .._model.energy import strain_rate_energy
from .._model.inertia import (
    PHI_INERTIA_FACTOR,
    body_dynamics,
    coriolis_forces,
    kinetic_energy,
    mass_matrix,
)
from .._model.inputs import (
    as_traced_leaves,
    check_controls,
    check_q,
    check_scene,
    frozen,
    solver_dtype,
    static_load_sites,
)
from .._model.kinematics import jacobian_and_value
from .._model.robot import concrete
from .._model.scene import Scene
from .._results import RESULTS
from .._statics.problem import ScaledProblem
from .damping import DEFAULT_DAMPING_RATIO, Damping, generalised_eigenvalues
from .rosenbrock import Rosenbrock23

__all__ = [
    "Damping",
    "Trajectory",
    "simulate",
    "Rosenbrock23",
    "rosenbrock23",
    "mass_matrix",
    "kinetic_energy",
    "coriolis_forces",
    "total_energy",
    "accelerations",
    "natural_frequencies",
    "DEFAULT_DAMPING_RATIO",
]


# ------------------------------------------------------------------------------ forces
class _Model(eqx.Module):
    """What the vector field needs, built once per simulation."""

    scene: Scene
    passive: Scene  # the scene without its tendons: their force is the motor law
    damping: Damping
    tendon_damping: Array | None
    phi_inertia: float = eqx.field(static=True)

    @staticmethod
    def build(scene: Scene, damping: Damping, phi_inertia: float, dtype) -> "_Model":
        passive = Scene(
            scene.robot,
            scene.models,
            loads=scene.loads,
            quadrature_points=scene.quadrature_points,
            rotation_substeps=scene.rotation_substeps,
        )
        kd = damping.tendon_gains(scene, dtype) if scene.tendons else None
        return _Model(scene, passive, damping, kd, phi_inertia)

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

    def _motor_law(self, lengths, rates, u, udot):
        """Tendon tensions (N) under the motor PD law, and their derivative in the tendon
        rates (the derivative gain while the tendon is taut, zero when slack or in tension
        mode)."""
        rest = self.scene.rest_tendon_lengths(lengths.dtype)
        tension, gains = [], []
        for i, t in enumerate(self.scene.tendons):
            if t.mode == "length":
                stretch = lengths[i] - (rest[i] - u[i])
                stretch_rate = rates[i] + udot[i]
                pull = (
                    t.gain.astype(lengths.dtype) * stretch + self.tendon_damping[i] * stretch_rate
                )
                tension.append(jnp.maximum(pull, 0.0))
                gains.append(jnp.where(pull > 0, self.tendon_damping[i], 0.0))
            else:
                tension.append(u[i])
                gains.append(jnp.zeros((), lengths.dtype))
        return jnp.stack(tension), jnp.stack(gains)

    def tendon_forces(self, q, qdot, u, udot):
        """``A(q) f_act``: generalised forces of the tendons under the motor PD law."""
        lengths, lin = jax.linearize(self.scene.tendon_lengths, q)
        tension, _ = self._motor_law(lengths, lin(qdot), u, udot)
        (force,) = jax.linear_transpose(lin, q)(-tension)
        return force

    def forces(self, q, qdot, u, udot, mass):
        """Every generalised force but inertia's: ``-G - K - D qdot + A f_act + Q_ext``, the
        mass-proportional damping on ``mass`` (``M(q)``, passed in to be computed once)."""
        force = -jax.grad(self.passive.potential_energy)(q, u)
        extra = self.passive.nonconservative_forces(q)
        if extra is not None:
            force = force + extra
        if self.scene.tendons:
            force = force + self.tendon_forces(q, qdot, u, udot)
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

    def frozen_inertia_jacobian(self, q, qdot, u, udot) -> Float[Array, "2n 2n"]:
        """``d(qdot, qddot) / d(q, qdot)`` with the inertia frozen, for a W-method
        (:class:`pacjax._dynamics.rosenbrock.Rosenbrock23`, whose order does not depend on it).

        ``qddot``'s rows are ``M(q)^-1 (dF/dq, dF/dqdot)`` with ``M`` held fixed, the Coriolis
        forces left out, ``dF/dq`` the Hessian of the potential energy with the tendons as the
        springs of their motors' proportional gains (the statics' energy), and ``dF/dqdot`` the
        damping: material, mass-proportional, and the motors' derivative gains on taut tendons.
        That is the stiff part of the dynamics; what is left out (the inertia's derivatives,
        and the damping forces' derivatives in ``q``) is as slow as the motion, and is the
        kinematics differentiated twice or three times.
        """
        n = q.shape[0]
        scene = self.scene
        mass = mass_matrix(scene, q, self.phi_inertia)
        d_q = -jax.hessian(scene.potential_energy)(q, u)
        if not self.passive.is_conservative:
            d_q = d_q + jax.jacfwd(self.passive.nonconservative_forces)(q)
        d_qdot = -self.damping.stiffness * jax.jacfwd(self.material_damping, argnums=1)(q, qdot)
        d_qdot = d_qdot - self.damping.mass * mass
        if scene.tendons:
            jac, lengths = jacobian_and_value(scene.tendon_lengths, q)
            _, gains = self._motor_law(lengths, jac @ qdot, u, udot)
            d_qdot = d_qdot - jnp.matmul(jac.T * gains, jac, precision=MATMUL_PRECISION)
        factor = jax.scipy.linalg.cho_factor(mass)
        lower = jax.scipy.linalg.cho_solve(factor, jnp.concatenate([d_q, d_qdot], axis=1))
        upper = jnp.concatenate([jnp.zeros((n, n), q.dtype), jnp.eye(n, dtype=q.dtype)], axis=1)
        return jnp.concatenate([upper, lower], axis=0)


def _control_fn(controls, n_tendons: int, dtype) -> Callable:
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
    model = _Model.build(scene, Damping() if damping is None else damping, phi_inertia, dtype)
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


# ------------------------------------------------------------------------------ simulate
class Trajectory(eqx.Module):
    """A simulated motion.

    Attributes:
        ts: (k,) save times (s).
        q: (k, n_dofs) configurations; ``qdot``: (k, n_dofs) velocities (per second).
        result: a :class:`pacjax.RESULTS` item: ``successful`` when the integration reached
            the final time, ``max_steps_reached`` or ``integration_failed`` when it stopped
            before (later saves are then infinite).
        num_steps: accepted plus rejected steps; ``num_accepted_steps``.
        solution: the diffrax solution (for :meth:`evaluate`) when simulated with ``dense``.
    """

    ts: Float[Array, " k"]
    q: Float[Array, "k n_dofs"]
    qdot: Float[Array, "k n_dofs"]
    result: RESULTS
    num_steps: Int[Array, ""]
    num_accepted_steps: Int[Array, ""]
    solution: diffrax.Solution | None = None

    @property
    def successful(self) -> Bool[Array, ""]:
        """``result == RESULTS.successful``: the integration reached the final time."""
        return self.result == RESULTS.successful

    @property
    def success(self) -> Bool[Array, ""]:
        """Deprecated: use :attr:`successful`."""
        _deprecated.warn("Trajectory.success", "Trajectory.successful")
        return self.successful

    def evaluate(self, t) -> tuple[Float[Array, "*k n_dofs"], Float[Array, "*k n_dofs"]]:
        """``(q, qdot)`` at any time(s) in the span, from the solver's dense output."""
        if self.solution is None:
            raise ValueError("Trajectory.evaluate needs simulate(..., dense=True)")
        t = jnp.asarray(t, self.ts.dtype)
        if t.ndim == 0:
            return self.solution.evaluate(t)
        return jax.vmap(self.solution.evaluate)(t)


class _Options(eqx.Module):
    solver: diffrax.AbstractSolver = eqx.field(static=True)
    rtol: float = eqx.field(static=True)
    atol: float = eqx.field(static=True)
    max_steps: int = eqx.field(static=True)
    dense: bool = eqx.field(static=True)
    phi_inertia: float = eqx.field(static=True)
    adjoint: diffrax.AbstractAdjoint = eqx.field(static=True)


def simulate(
    scene: Scene,
    t_span,
    controls=None,
    q0=None,
    qdot0=None,
    saveat=None,
    *,
    damping: Damping | None = None,
    solver: diffrax.AbstractSolver | None = None,
    rtol: float = 1e-7,
    atol: float = 1e-9,
    dt0=None,
    max_steps: int = 100_000,
    dense: bool = False,
    phi_inertia: float = PHI_INERTIA_FACTOR,
    adjoint: diffrax.AbstractAdjoint | None = None,
) -> Trajectory:
    """Simulate the full dynamics of ``scene`` over ``t_span = (t0, t1)`` (s).

    Args:
        scene: the :class:`Scene` (every segment needs ``linear_density > 0``).
        t_span: ``(t0, t1)``, s.
        controls: (n_tendons,) constant controls (pull-in in m, or tension in N), or a callable
            ``t -> (n_tendons,)`` (differentiable in ``t``: its derivative is the commanded
            ``l_bar_dot``; pass the same function object again to reuse the compiled solver).
            Default zeros.
        q0, qdot0: initial state (default straight and at rest). For PCC/PAC, the
            bending-plane angle of a straight segment at rest is first turned to the force on
            it at ``t0``.
        saveat: times (s) to save at (default 101 evenly spaced over ``t_span``).
        damping: a :class:`Damping`; default :meth:`Damping.modal` (5 % on the lowest mode,
            stiffness-proportional, motors ``kappa_D = beta kappa_P``). ``Damping()``: none.
        solver: a diffrax solver. Default: for ``rtol >= 1e-5``, :func:`rosenbrock23` (a
            linearly implicit method with the dynamics' stiff Jacobian: cheap steps for
            control and learning); tighter, ``diffrax.Kvaerno5`` with
            :class:`pacjax._chord.DenseChord` (diffrax's chord method with a forward-mode
            Jacobian). A non-stiff solver such as ``diffrax.Tsit5()`` only suits scenes without
            stiff tendons or damping.
        rtol, atol: tolerances of the adaptive step size (``atol`` in the state's SI units).
        dt0: first step (s); default chosen by the solver.
        max_steps: step limit (beyond it the trajectory's ``result`` is
            ``RESULTS.max_steps_reached``).
        dense: keep the dense output (:meth:`Trajectory.evaluate`).
        phi_inertia: regularising inertia factor on PCC/PAC's ``phi`` (see
            :mod:`pacjax._model.inertia`).
        adjoint: diffrax adjoint for gradients (default ``RecursiveCheckpointAdjoint``).

    Returns:
        A :class:`Trajectory`; differentiable with respect to scene parameters, damping,
        controls and initial state.

    PCC and PAC through straight segments: their polar coordinates are singular there (the
    force on ``phi`` vanishes with the curvature), so the motion of a segment that is loaded
    while straight depends on its ``phi``: with every ``phi = 0`` a segment pulled by a tendon
    off its plane stays on the saddle and barely moves in the first milliseconds, where turned
    to its tendon it bends at once (``benchmarks/RESULTS.md``, "Figures behind the solver's
    settings"). The default turns each straight segment to the force on it at ``t0``, and the
    unloaded ones to their predecessor's plane. Use ``PolynomialCurvature`` (order 1 is PAC's
    affine law in Cartesian form) to simulate motion through straight segments.
    """
    check_scene(scene)
    dtype = solver_dtype(scene)
    t0, t1 = check_span(t_span)
    controls = check_simulation_controls(scene, controls, t0, dtype)
    q0 = check_q(scene, q0, dtype)
    qdot0 = check_qdot(scene, qdot0, dtype)
    scene, damping, opts, span, ts = prepare(
        scene, t0, t1, saveat, damping, solver, rtol, atol, max_steps, dense, phi_inertia, adjoint
    )
    q0 = aligned_rest_start(scene, controls, q0, qdot0, span[0])
    dt0 = None if dt0 is None else jnp.asarray(dt0, dtype)
    return integrate(scene, damping, controls, q0, qdot0, span, ts, dt0, opts)


def check_qdot(scene: Scene, qdot0, dtype):
    if qdot0 is None:
        return jnp.zeros(scene.n_dofs, dtype)
    if np.shape(qdot0) != (scene.n_dofs,):
        raise ValueError(f"qdot0 must have shape ({scene.n_dofs},), got {np.shape(qdot0)}")
    return jnp.asarray(qdot0, dtype)


def prepare(
    scene, t0, t1, saveat, damping, solver, rtol, atol, max_steps, dense, phi_inertia, adjoint
):
    """What one simulation and a batch (:mod:`pacjax._dynamics.batch`) share: the checked body,
    times, damping and options."""
    dtype = solver_dtype(scene)
    _check_body(scene)
    ts = _check_saveat(saveat, t0, t1)
    if not (rtol > 0 and atol > 0):
        raise ValueError(f"rtol and atol must be > 0, got {rtol}, {atol}")
    if max_steps < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}")
    if not phi_inertia >= 0:
        raise ValueError(f"phi_inertia must be >= 0, got {phi_inertia}")
    # Known point-mass sites become knots of the kinematics (as in the statics): a traced site
    # integrates its own frame in every kinematics pass, and the vector field has several.
    scene = static_load_sites(as_traced_leaves(scene, dtype))
    damping = _check_damping(scene, damping)
    opts = _Options(
        solver=default_solver(rtol) if solver is None else solver,
        rtol=float(rtol),
        atol=float(atol),
        max_steps=int(max_steps),
        dense=bool(dense),
        phi_inertia=float(phi_inertia),
        adjoint=diffrax.RecursiveCheckpointAdjoint() if adjoint is None else adjoint,
    )
    span = jnp.asarray([t0, t1], dtype)
    return scene, damping, opts, span, jnp.asarray(ts, dtype)


def _check_body(scene: Scene) -> None:
    """A body that has a mass matrix: mass on every segment, and a radius for twist."""
    for i, seg in enumerate(scene.robot.segments):
        density = concrete(seg.linear_density)
        if density is not None and not density > 0:
            raise ValueError(
                f"Robot.segments[{i}].linear_density must be > 0 to simulate dynamics "
                f"(the mass matrix would be singular), got {density}"
            )
    if scene.model.has_twist_strain():
        for i, seg in enumerate(scene.robot.segments):
            radius = concrete(seg.radius)
            if radius is not None and not radius > 0:
                raise ValueError(
                    f"Robot.segments[{i}].radius must be > 0 to simulate a twisting model "
                    "(twist moves no mass on a zero-radius body)"
                )


def check_simulation_controls(scene: Scene, controls, t0: float, dtype):
    """Constant controls checked as a solve's; a schedule ``controls(t)`` by its output shape."""
    if not callable(controls):
        return check_controls(scene, controls, dtype)
    shape = jax.eval_shape(controls, jnp.asarray(t0, dtype)).shape
    if shape != (scene.n_tendons,):
        raise ValueError(
            f"controls(t) must return shape ({scene.n_tendons},) (one per tendon), got {shape}"
        )
    return controls


def _check_damping(scene: Scene, damping) -> Damping:
    """The given damping, or the default modal one (5 % on the lowest mode)."""
    if damping is None:
        return Damping.modal(scene)
    if not isinstance(damping, Damping):
        raise TypeError(f"damping must be a pacjax.Damping, got {type(damping).__name__}")
    if damping.tendon is not None and jnp.ndim(damping.tendon) == 1:
        if damping.tendon.shape != (scene.n_tendons,):
            raise ValueError(
                f"Damping.tendon must have shape ({scene.n_tendons},), got {damping.tendon.shape}"
            )
    return damping


@eqx.filter_jit
def aligned_rest_start(scene: Scene, controls, q0, qdot0, t0):
    """``q0`` with the bending plane of each straight PCC/PAC segment at rest turned to the
    force on it at ``t0`` (:meth:`pacjax._statics.problem.ScaledProblem.aligned`).

    A straight segment's ``phi`` is undefined, and the force on ``phi`` vanishes there, so the
    polar coordinates can only start bending it in the plane ``phi`` names: a segment pulled
    at right angles to that plane stays straight on a saddle of the dynamics until round-off
    tips it over. The configuration is the same; only its coordinates change, and the
    derivative with respect to ``q0`` passes through unchanged. A segment that is already
    moving keeps its ``phi``: the plane of its velocity is then defined by it. A straight
    segment with no force on it at ``t0`` takes the plane of the segment before it, through
    which it will be loaded first (see :func:`simulate`).
    """
    k = scene.model.free_plane_angle()
    if k is None:
        return q0
    u0 = controls(t0) if callable(controls) else controls
    moving = jnp.any(scene.coordinates(qdot0)[:, :k] != 0, axis=1)
    problem = frozen(ScaledProblem.build(scene, jnp.asarray(u0, q0.dtype)))
    y = problem.aligned(jax.lax.stop_gradient(q0) / problem.sigma, 1e-10, keep=moving)
    return q0 + jax.lax.stop_gradient(problem.sigma * y - q0)


def check_span(t_span) -> tuple[float, float]:
    span = np.asarray(t_span, dtype=float)
    if span.shape != (2,) or not np.all(np.isfinite(span)) or not span[1] > span[0]:
        raise ValueError(f"t_span must be (t0, t1) with finite t1 > t0, got {t_span!r}")
    return float(span[0]), float(span[1])


def _check_saveat(saveat, t0: float, t1: float) -> np.ndarray:
    if saveat is None:
        return np.linspace(t0, t1, 101)
    ts = np.atleast_1d(np.asarray(saveat, dtype=float))
    if ts.ndim != 1 or ts.size == 0:
        raise ValueError(f"saveat must be a 1D array of times, got shape {ts.shape}")
    if np.any(~np.isfinite(ts)) or np.any(ts < t0) or np.any(ts > t1):
        raise ValueError(f"saveat times must lie in t_span [{t0}, {t1}]")
    if np.any(np.diff(ts) < 0):
        raise ValueError("saveat times must be non-decreasing")
    return ts


@eqx.filter_jit
def _result(result: diffrax.RESULTS) -> RESULTS:
    """diffrax's result as pacjax's: the step limit, or any other failure to reach ``t1``."""
    failed = RESULTS.where(
        result == diffrax.RESULTS.max_steps_reached,
        RESULTS.max_steps_reached,
        RESULTS.integration_failed,
    )
    return RESULTS.where(result == diffrax.RESULTS.successful, RESULTS.successful, failed)


def _vector_field(t, y, args):
    """``(qdot, qddot)``. A jitted function of its arguments (the model and controls come in
    ``args``, not by closure): its trace, and the traces of its derivatives, are made once and
    reused everywhere the solver calls or differentiates it."""
    model, controls = args
    q, qdot = y
    u, udot = _control_fn(controls, model.scene.n_tendons, q.dtype)(t)
    return qdot, model.accelerations(q, qdot, u, udot)


def _vector_field_jacobian(t, y, args):
    """:meth:`_Model.frozen_inertia_jacobian` along the flattened state ``(q, qdot)``."""
    model, controls = args
    q, qdot = y
    u, udot = _control_fn(controls, model.scene.n_tendons, q.dtype)(t)
    return model.frozen_inertia_jacobian(q, qdot, u, udot)


def rosenbrock23() -> Rosenbrock23:
    """:class:`Rosenbrock23` with the dynamics' frozen-inertia Jacobian
    (:meth:`_Model.frozen_inertia_jacobian`): :func:`simulate`'s solver at moderate tolerances."""
    return Rosenbrock23(jacobian=_vector_field_jacobian)


#: ``rtol`` from which :func:`simulate` takes :func:`rosenbrock23` by default (Kvaerno5 below).
ROSENBROCK_RTOL = 1e-5


def default_solver(rtol: float) -> diffrax.AbstractSolver:
    """:func:`rosenbrock23` from ``rtol >= ROSENBROCK_RTOL``: one Jacobian, one factorisation
    and two vector fields a step; below it Kvaerno5 with :class:`pacjax._chord.DenseChord`, whose
    fifth order takes fewer (dearer) steps to a tight tolerance."""
    return rosenbrock23() if rtol >= ROSENBROCK_RTOL else kvaerno5()


@eqx.filter_jit
def integrate(scene, damping, controls, q0, qdot0, span, ts, dt0, opts: _Options):
    """The compiled simulation of checked inputs (:func:`prepare`, :func:`aligned_rest_start`):
    one row of :func:`pacjax._dynamics.batch.simulate_batch`."""
    model = _Model.build(scene, damping, opts.phi_inertia, q0.dtype)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_vector_field),
        opts.solver,
        t0=span[0],
        t1=span[1],
        dt0=dt0,
        y0=(q0, qdot0),
        saveat=diffrax.SaveAt(ts=ts, dense=opts.dense),
        stepsize_controller=diffrax.PIDController(rtol=opts.rtol, atol=opts.atol),
        args=(model, controls),
        max_steps=opts.max_steps,
        adjoint=opts.adjoint,
        throw=False,
    )
    q, qdot = sol.ys
    return Trajectory(
        ts=sol.ts,
        q=q,
        qdot=qdot,
        result=_result(sol.result),
        num_steps=sol.stats["num_steps"],
        num_accepted_steps=sol.stats["num_accepted_steps"],
        solution=sol if opts.dense else None,
    )
