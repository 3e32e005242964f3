"""Static equilibrium: continuation of the damped flow to a steady state, with stability.

The paper finds equilibria by integrating the damped flow ``D qdot = -F(q)`` to a steady state.
That flow is stiff (tendon gains against a soft body): an explicit integrator needs tens of
thousands of steps. pacjax integrates it with linearised implicit Euler steps whose size grows as
the residual falls (pseudo-transient continuation, :mod:`pacjax._ptc`): far from equilibrium the
steps follow the flow, near it they are Newton steps with the exact Jacobian, so the last steps
*are* the Newton polish. ``D`` is the diagonal of the elastic stiffness, so the flow is well
scaled. The loop runs inside ``optimistix.root_find`` with the implicit adjoint, so derivatives of
the equilibrium with respect to any scene parameter or control come from the implicit function
theorem (one linear solve), never from differentiating the iterations.

``method="flow"`` first integrates the preconditioned flow with ``diffrax`` (an adaptive implicit
Runge-Kutta method, stopped by a steady-state event) and then continues from there: slower, and
the automatic fallback when continuation from the given start fails.

An equilibrium that is a saddle (a column past buckling; PAC's straight state where ``phi`` is
undefined) is detected from the smallest eigenvalue of the scaled stiffness and, by default, left
along its direction of negative curvature.
"""

import dataclasses

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import lineax as lx
import numpy as np
import optimistix as optx

from ._chord import kvaerno5
from ._continuation import (
    conservative_part,
    keep_better,
    load_continuation,
    order_continuation,
    order_step,
)
from ._hessian import dead_followers, energy_derivatives, follower_jacobian
from ._jit import jit
from ._ptc import PseudoTransientContinuation, final_code, max_abs
from ._robot import concrete
from ._scene import Scene, SceneConstants
from ._solution import Equilibrium


class SolverOptions(eqx.Module):
    """Static solver settings (changing one recompiles).

    Args:
        tol: tolerance on the scaled residual (see :class:`Equilibrium`).
        max_steps: maximum continuation steps (per escape attempt).
        initial_dt: first pseudo-time step, in units of the elastic relaxation time.
        max_dt: largest pseudo-time step (Newton beyond it).
        escapes: how many times a converged saddle is left along its negative-curvature
            direction and continued again (0: report saddles as they are).
        escape_size: size of that perturbation (rad of curvature).
        stability_tol: threshold on the smallest scaled eigenvalue for ``stable``.
        method: ``"ptc"`` (continuation, default) or ``"flow"`` (diffrax).
        flow_solver: diffrax solver of the flow method (default ``diffrax.Kvaerno5`` with
            :class:`pacjax._chord.DenseChord`).
        hessian: ``"structured"`` (default: per-segment forward derivatives of the kinematics,
            :mod:`pacjax._hessian`, plus the forward derivative of the follower loads alone
            in a non-conservative scene) or ``"autodiff"`` (``jax.jacfwd`` of the residual).
            Both are exact; they differ in cost.
    """

    tol: float = eqx.field(static=True, default=1e-10)
    max_steps: int = eqx.field(static=True, default=100)
    initial_dt: float = eqx.field(static=True, default=1.0)
    max_dt: float = eqx.field(static=True, default=1e12)
    escapes: int = eqx.field(static=True, default=2)
    escape_size: float = eqx.field(static=True, default=0.05)
    stability_tol: float | None = eqx.field(static=True, default=None)
    method: str = eqx.field(static=True, default="ptc")
    flow_solver: diffrax.AbstractSolver = eqx.field(static=True, default=kvaerno5())
    hessian: str = eqx.field(static=True, default="structured")

    def __check_init__(self):
        if self.hessian not in ("structured", "autodiff"):
            raise ValueError(f"hessian must be 'structured' or 'autodiff', got {self.hessian!r}")
        if self.method not in ("ptc", "flow"):
            raise ValueError(f"method must be 'ptc' or 'flow', got {self.method!r}")
        for name in ("max_steps", "escapes"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise TypeError(f"{name} must be an integer, got {value!r}")
        for name in ("tol", "initial_dt", "max_dt", "escape_size", "stability_tol"):
            value = getattr(self, name)
            if value is None and name == "stability_tol":
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)):
                raise TypeError(f"{name} must be a number, got {value!r}")
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {self.max_steps}")
        if self.escapes < 0:
            raise ValueError(f"escapes must be >= 0, got {self.escapes}")
        if not isinstance(self.flow_solver, diffrax.AbstractSolver):
            raise TypeError(f"flow_solver must be a diffrax solver, got {self.flow_solver!r}")


class _Scaled(eqx.Module):
    """The equilibrium problem in scaled coordinates ``y = q / sigma``.

    The residual ``r(y) = F(sigma y) / (d sigma)`` is dimensionless (``d`` the diagonal of the
    elastic stiffness); ``D = diag(d)`` is the damping of the flow.
    """

    scene: Scene
    controls: jax.Array
    sigma: jax.Array
    row: jax.Array
    consts: SceneConstants
    # Follower forces as dead ones (``pacjax._hessian.dead_followers``), for the Jacobian.
    dead_scene: Scene | None = None
    dead_consts: SceneConstants | None = None
    dead_index: tuple[int, ...] = eqx.field(static=True, default=())

    @staticmethod
    def build(scene: Scene, controls: jax.Array) -> "_Scaled":
        """The scaled problem; the scene's parameter-only terms are computed here, once, not
        in every energy evaluation of the solver loop (they stay differentiable)."""
        dtype = controls.dtype
        sigma = jax.lax.stop_gradient(scene.coordinate_scale(dtype))
        d = jax.lax.stop_gradient(scene.elastic_stiffness_diagonal(dtype))
        dead = None if scene.is_conservative else dead_followers(scene)
        dead_scene, index = (None, ()) if dead is None else dead
        dead_consts = None if dead is None else dead_scene.constants(dtype)
        return _Scaled(
            scene,
            controls,
            sigma,
            1.0 / (d * sigma),
            scene.constants(dtype),
            dead_scene,
            dead_consts,
            index,
        )

    def q(self, y):
        return self.sigma * y

    def residual(self, y):
        return self.scene.residual(self.q(y), self.controls, self.consts) * self.row

    def residual_and_merit(self, y):
        """Scaled residual and the potential energy of the conservative part (J), the merit
        of the continuation (with the non-conservative forces frozen, see :meth:`drive`)."""
        q = self.q(y)
        energy, grad = jax.value_and_grad(self.scene.potential_energy)(
            q, self.controls, self.consts
        )
        if not self.scene.is_conservative:
            grad = grad - self.scene.nonconservative_forces(q)
        return grad * self.row, energy

    def drive(self, y):
        """Non-conservative generalised forces in scaled coordinates: ``r = dE/dy - drive``
        up to the row scale (``frozen_work`` of :class:`PseudoTransientContinuation`)."""
        return self.sigma * self.scene.nonconservative_forces(self.q(y))

    def energy(self, y):
        """Potential energy (J) at ``y``: the merit of a conservative scene, without its
        gradient."""
        return self.scene.potential_energy(self.q(y), self.controls, self.consts)

    def linearise(self, y):
        """Scaled residual and its Jacobian, ``(dr/dy, (r, (merit, weights)))``, from the
        structured Hessian of the potential energy. Follower forces of a PCC/PAC scene enter
        it as dead forces plus the turning of their direction
        (:func:`pacjax._hessian.follower_jacobian`; the residual is :meth:`residual_and_merit`'s).
        Other non-conservative scenes add the forward derivative of their non-conservative
        loads alone (a few points of the kinematics), not of the whole residual: on 2 CPU cores
        a warm batch of 24 equilibria of the paper's robot with ``PolynomialCurvature(6)`` (12
        points) under a 3.41 N follower force took 174 s against 196 s."""
        q = self.q(y)
        if self.dead_scene is not None:
            hessian = follower_jacobian(
                self.scene, self.dead_scene, self.dead_index, q, self.controls, self.dead_consts
            )
            r, energy = self.residual_and_merit(y)
            jac = self.row[:, None] * hessian * self.sigma[None, :]
            return jac, (r, (energy, self.weights()))
        energy, grad, hessian = energy_derivatives(self.scene, q, self.controls, self.consts)
        merit = energy
        if not self.scene.is_conservative:

            def forces(x):
                value = self.scene.nonconservative_forces(x)
                return value, value

            d_forces, value = jax.jacfwd(forces, has_aux=True)(q)
            grad, hessian = grad - value, hessian - d_forces
        jac = self.row[:, None] * hessian * self.sigma[None, :]
        return jac, (grad * self.row, (merit, self.weights()))

    def moved(self, y, dy):
        """The iterate after the continuation step ``dy`` from ``y``: ``y + dy``, except for the
        bending of a PCC/PAC segment whose plane angle ``phi`` is free (torsion-free frame) and
        whose end is turned (``theta = beta . c != 0``, the bending angle at its end).

        There the curvatures ``c`` and ``phi`` are polar coordinates. A tendon's length in the
        segment, ``-r theta cos(phi - alpha)`` up to the chords, is linear in the bending vector
        ``B = theta e(phi)`` (``e(phi)`` the plane's direction) and bilinear in ``(c, phi)``, so
        steps along ``phi`` crept (3-4 steps for the plane's turn on the paper's robot). The
        step is taken on ``B``: ``B' = B + dtheta e(phi) + theta dphi e'(phi)``, the plane
        turned to ``B'`` by less than a quarter turn (a bend that passes through straight goes
        on with ``theta < 0``), and every curvature carried along as a vector in the plane,
        ``c' = (c + dc) cos(turn) + c dphi sin(turn)``, so that ``theta' e(phi') = B'``. This
        agrees with ``y + dy`` to first order: the step's descent and the search along it are
        unchanged. On the paper's robot with PAC (64 random commands, 200 g tip mass) a row took
        6.5 continuation steps (mean) against 8.0; moving the plane to the principal axis of
        the curvatures' vectors instead took 6.9-7.0.
        """
        k = self.scene.model.free_plane_angle()
        if k is None:
            return y + dy
        n, d = self.scene.n_segments, self.scene.dofs_per_segment
        q = (self.sigma * y).reshape(n, d)
        dq = (self.sigma * dy).reshape(n, d)
        beta = self.scene.model.plane_angle_basis(jnp.ones((), y.dtype))
        c, dc, dphi = q[:, :k], dq[:, :k], dq[:, k]
        theta = c @ beta
        ahead = theta + dc @ beta
        # The angle of B' from e(phi), in (-pi/2, pi/2]: arctan(theta dphi / (theta + dtheta)).
        turn = jnp.arctan2(theta * dphi * jnp.where(ahead < 0, -1.0, 1.0), jnp.abs(ahead))
        c_new = (c + dc) * jnp.cos(turn)[:, None] + c * (dphi * jnp.sin(turn))[:, None]
        # An end that is not turned (straight, or an S of PAC) has no B to move: y + dy.
        flat = theta == 0
        c_new = jnp.where(flat[:, None], c + dc, c_new)
        turn = jnp.where(flat, dphi, turn)
        q_new = (q + dq).at[:, :k].set(c_new).at[:, k].set(q[:, k] + turn)
        return q_new.reshape(-1) / self.sigma

    def aligned(self, y, tol: float, keep=None):
        """``y`` with the bending plane of each straight segment turned to the force on it.

        A PCC/PAC segment's bending-plane angle ``phi`` is undefined while it is straight (the
        shape does not depend on it), so a straight start is a degenerate saddle: the
        continuation first bends the segments in whatever plane ``phi`` says and then turns the
        planes, with an indefinite stiffness all the while (on the paper's robot, 13 steps
        from straight against 9 from aligned planes, batch mean). At zero curvature the force on
        ``c0`` is exactly ``a cos(phi) + b sin(phi)``, since it is linear in the bending
        direction ``(cos(phi), sin(phi))``: the residuals at ``phi = 0`` and ``pi / 2`` give
        the plane of steepest descent. ``phi`` is taken in ``(-pi/2, pi/2]``, the half that the
        regulariser ``k (1 - cos(phi))`` prefers; the sign of ``c0`` then picks the side. A
        segment that is bent keeps its ``phi``, and so does one where ``keep`` (a boolean per
        segment) says so. A straight segment whose force is below ``tol`` (scaled) takes the
        plane of the segment before it (the first segment keeps its ``phi``).
        """
        k = self.scene.model.free_plane_angle()
        if k is None:
            return y
        n, d = self.scene.n_segments, self.scene.dofs_per_segment
        coords = y.reshape(n, d)
        straight = jnp.all(coords[:, :k] == 0, axis=1)
        if keep is not None:
            straight = straight & ~keep

        def force_on_c0(phi):
            trial = coords.at[:, k].set(jnp.where(straight, phi, coords[:, k]))
            return self.residual(trial.reshape(-1)).reshape(n, d)[:, 0]

        # One batched residual (one copy of its graph to compile).
        a, b = jax.vmap(force_on_c0)(jnp.asarray([0.0, 0.5 * np.pi], y.dtype))
        phi = jnp.arctan2(-b, -a)
        phi = jnp.where(phi > 0.5 * np.pi, phi - np.pi, phi)
        phi = jnp.where(phi <= -0.5 * np.pi, phi + np.pi, phi)
        turn = straight & (jnp.hypot(a, b) > tol) & jnp.isfinite(phi)
        phi = jnp.where(turn, phi, coords[:, k])
        # A straight segment with no force on it is loaded only through the segments before
        # it, which bend in their own planes: it takes its predecessor's plane. (Kept at its
        # phi, it meets a saddle in that plane: the paper's robot pulled by one tendon of
        # section 1 took 34-40 steps against 9.)
        inherit = straight & ~turn
        for i in range(1, n):
            phi = phi.at[i].set(jnp.where(inherit[i], phi[i - 1], phi[i]))
        return coords.at[:, k].set(phi).reshape(-1)

    def weights(self):
        """``sqrt(d) sigma``: maps scaled coordinates to ``D^1/2``-weighted ones."""
        return jnp.sqrt(self.sigma / self.row)

    @staticmethod
    def root_fn(y, args: "_Scaled"):
        """``(r, (merit, weights))`` for :class:`PseudoTransientContinuation`."""
        r, merit = args.residual_and_merit(y)
        return r, (merit, args.weights())


@eqx.filter_jit
def _flow(t, y, problem: _Scaled):
    """``-r(y)``, jitted on its own so that the solver's calls and derivatives share one trace
    (the problem comes in diffrax's ``args``)."""
    return -problem.residual(y)


def _flow_start(problem: _Scaled, y0, opts: SolverOptions):
    """Integrate the preconditioned flow ``dy/dt = -r(y)`` with diffrax towards a steady state."""
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_flow),
        opts.flow_solver,
        t0=0.0,
        t1=jnp.inf,
        dt0=None,
        y0=y0,
        args=problem,
        stepsize_controller=diffrax.PIDController(rtol=1e-6, atol=1e-9),
        event=diffrax.Event(diffrax.steady_state_event(rtol=0.0, atol=opts.tol * 100)),
        max_steps=opts.max_steps * 100,
        throw=False,
    )
    return sol.ys[-1], sol.stats["num_steps"]


def _stability_tol(opts, dtype):
    return (
        opts.stability_tol if opts.stability_tol is not None else 1e3 * float(jnp.finfo(dtype).eps)
    )


def make_solver(scene: Scene, opts: SolverOptions, dtype) -> PseudoTransientContinuation:
    """The continuation root finder for a scene's structure and the solver options."""
    return PseudoTransientContinuation(
        rtol=0.0,
        atol=opts.tol,
        initial_dt=opts.initial_dt,
        max_dt=opts.max_dt,
        escapes=opts.escapes,
        escape_size=opts.escape_size,
        stability_tol=_stability_tol(opts, dtype),
        symmetric=scene.is_conservative,
        frozen_work=not scene.is_conservative,
        structured=opts.hessian == "structured",
    )


def max_total_steps(opts: SolverOptions) -> int:
    """Continuation steps allowed in all (``max_steps`` per escape attempt)."""
    return opts.max_steps * (1 + opts.escapes)


def start_point(problem: "_Scaled", q0, opts: SolverOptions):
    """Scaled starting point ``y0 = q0 / sigma``, its straight segments' bending planes turned
    to the force (:meth:`_Scaled.aligned`); no derivative flows through the start."""
    frozen = jax.lax.stop_gradient(problem)
    return frozen.aligned(jax.lax.stop_gradient(q0) / frozen.sigma, opts.tol)


def equilibrium_from(
    scene: Scene, problem: "_Scaled", solver, y, state, steps, tol: float
) -> Equilibrium:
    """The :class:`Equilibrium` at the continuation's final iterate ``y`` and state."""
    residual_norm = max_abs(state.residual)
    converged = residual_norm <= tol
    energy = state.merit if scene.is_conservative else jnp.asarray(jnp.nan, state.merit.dtype)
    return Equilibrium(
        q=jax.lax.stop_gradient(problem.sigma) * y,
        converged=converged,
        residual_norm=residual_norm,
        stable=state.eig > -solver.stability_tol,
        min_hessian_eigenvalue=state.eig,
        steps=steps,
        result=final_code(state, converged),
        energy=energy,
    )


def solve_core(scene: Scene, controls, q0, opts: SolverOptions) -> Equilibrium:
    """One equilibrium (traceable; :func:`solve_equilibrium` and the batch solver wrap it)."""
    problem = _Scaled.build(scene, controls)
    frozen = jax.lax.stop_gradient(problem)
    y0 = start_point(problem, q0, opts)
    flow_steps = jnp.asarray(0)
    if opts.method == "flow":
        y0, flow_steps = _flow_start(frozen, y0, opts)
    solver = make_solver(scene, opts, q0.dtype)
    sol = optx.root_find(
        _Scaled.root_fn,
        solver,
        y0,
        args=problem,
        has_aux=True,
        max_steps=max_total_steps(opts),
        throw=False,
        adjoint=optx.ImplicitAdjoint(linear_solver=lx.LU()),
    )
    steps = sol.stats["num_steps"] + flow_steps
    return equilibrium_from(scene, frozen, solver, sol.value, sol.state, steps, opts.tol)


_solve = jit(solve_core)


def check_controls(scene: Scene, controls, dtype, batched: bool = False) -> jax.Array:
    """Validate controls against the scene (before any compilation).

    A single solve takes exactly ``(n_tendons,)``; a batch ``(batch, n_tendons)``.
    """
    if controls is None:
        return scene.default_controls(dtype)
    arr = None
    if not isinstance(controls, jax.core.Tracer):
        try:
            arr = np.asarray(controls, dtype=float)
        except (TypeError, ValueError):
            raise TypeError(f"controls must be real numbers, got {controls!r}") from None
    shape = arr.shape if arr is not None else jnp.shape(controls)
    want = ("batch", scene.n_tendons) if batched else (scene.n_tendons,)
    if len(shape) != len(want) or shape[-1] != scene.n_tendons:
        hint = " (use pacjax.solve_batch for many commands)" if len(shape) > len(want) else ""
        raise ValueError(
            f"controls must have shape {want} (one per tendon), got {shape}{hint}".replace(
                "'batch'", "batch"
            )
        )
    if arr is not None:
        if not np.all(np.isfinite(arr)):
            raise ValueError("controls contain NaN or infinite values")
        for i, t in enumerate(scene.tendons):
            if t.mode == "tension" and np.any(arr[..., i] < 0):
                raise ValueError(
                    f"controls[{i}] is a tension and must be >= 0 (tendons never push)"
                )
    return jnp.asarray(controls, dtype)


def check_q(scene: Scene, q, dtype) -> jax.Array:
    if q is None:
        return scene.zeros(dtype)
    if not isinstance(q, jax.core.Tracer):
        try:
            q = np.asarray(q, dtype=float)
        except (TypeError, ValueError):
            raise TypeError(f"q0 must be an array of real numbers, got {q!r}") from None
    shape = np.shape(q) if not isinstance(q, jax.core.Tracer) else jnp.shape(q)
    if shape != (scene.n_dofs,):
        raise ValueError(f"q0 must have shape ({scene.n_dofs},), got {shape}")
    if not isinstance(q, jax.core.Tracer):
        if not np.all(np.isfinite(np.asarray(q, float))):
            raise ValueError("q0 contains NaN or infinite values")
        check_start_contraction(scene, np.asarray(q, float)[None])
    return jnp.asarray(q, dtype)


def check_start_contraction(scene: Scene, qs: np.ndarray) -> None:
    """Raise a ValueError naming ``q0`` when a start contracts a segment to or past its stop.

    There the energy is infinite (:func:`pacjax._energy.contraction_stop_energy`): no solver
    can start from it. ``qs`` is (rows, n_dofs) of known values.
    """
    known = [concrete(seg.contraction_limit) for seg in scene.robot.segments]
    if any(x is None for x in known):
        return
    limits = np.asarray(known, float)
    # Evaluated now even inside a jit trace (a known q0 closed over by a jitted function).
    with jax.ensure_compile_time_eval():
        coords = jax.vmap(scene.coordinates)(jnp.asarray(qs))
        elongation = np.asarray(jax.vmap(jax.vmap(scene.model.elongation))(coords))
    past = -elongation >= limits[None]
    if np.any(past):
        row, seg = np.argwhere(past)[0]
        where = f" (row {row})" if qs.shape[0] > 1 else ""
        raise ValueError(
            f"q0{where} contracts segment {seg} by {-elongation[row, seg]:.6g} m, at or past its "
            f"contraction_limit {float(limits[seg]):.6g} m (infinite energy: no solver can start "
            "there)"
        )


def as_traced_leaves(scene: Scene, dtype) -> Scene:
    """Python numbers put into a scene (e.g. by ``eqx.tree_at``) become arrays.

    ``jit`` would treat them as compile-time constants and recompile for every new value.
    """

    def convert(x):
        if isinstance(x, (float, int)) and not isinstance(x, bool):
            return jnp.asarray(x, dtype)
        return x

    return jtu.tree_map(convert, scene)


def static_load_sites(scene: Scene) -> Scene:
    """Load sites (``s`` of point masses, forces and moments) whose value is known now become
    Python floats, which ``jit`` treats as compile-time constants.

    A known site is a knot of the kinematics, evaluated with the tendon guides for free; a traced
    one costs its own frame integration and its own Hessian block in every solver step (it more
    than doubled the compiled solver of the paper's robot). A new site value compiles again; a
    site set per row (``solve_batch(params=..., update=...)``) or differentiated stays traced.
    """
    loads = []
    for load in scene.loads:
        site = getattr(load, "s", None)
        value = None if site is None or isinstance(site, jax.core.Tracer) else concrete(site)
        if value is not None and value.shape == ():
            load = eqx.tree_at(lambda x: x.s, load, float(value))
        loads.append(load)
    return eqx.tree_at(lambda sc: sc.loads, scene, tuple(loads))


def solver_dtype(scene: Scene):
    """The floating dtype the scene's parameters are stored in."""
    leaves = [x for x in jtu.tree_leaves(scene) if eqx.is_inexact_array(x)]
    return leaves[0].dtype if leaves else jnp.float64


def solve_equilibrium(
    scene: Scene, controls=None, q0=None, *, fallback: bool = True, **options
) -> Equilibrium:
    """Static equilibrium of ``scene`` under ``controls`` (one per tendon), starting from ``q0``.

    Args:
        scene: the :class:`Scene`.
        controls: (n_tendons,) pull-in (m) for length-mode tendons, tension (N) for tension-mode
            ones; default zeros.
        q0: starting configuration (default straight). A straight PCC/PAC segment's
            bending-plane angle is first turned to the force on it (:meth:`_Scaled.aligned`).
        fallback: when continuation fails, retry with the diffrax flow (outside jit, compiled
            only when needed). Whatever ``fallback`` says, a failed solve is first retried by
            load continuation for a non-conservative scene (follower forces, dead moments; from
            the equilibrium of its conservative part), then, for ``PolynomialCurvature`` of
            order >= 2, by order continuation (from the equilibrium one order lower,
            :func:`order_step`).
        **options: :class:`SolverOptions` fields (``tol``, ``max_steps``, ``escapes``, ...).

    Returns:
        An :class:`Equilibrium`. Differentiable with respect to the scene's parameters and the
        controls (implicit function theorem); ``jit``/``vmap`` compatible.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a pacjax.Scene, got {type(scene).__name__}")
    opts = SolverOptions(**options)
    dtype = solver_dtype(scene)
    scene = static_load_sites(as_traced_leaves(scene, dtype))
    controls = check_controls(scene, controls, dtype)
    q0 = check_q(scene, q0, dtype)
    eq = _solve(scene, controls, q0, opts)
    if opts.method == "ptc" and not _is_traced(eq.converged):
        if not bool(np.all(eq.converged)) and not scene.is_conservative:

            def solve(conservative, start):
                sc = conservative_part(scene) if conservative else scene
                return _solve(sc, controls, start, opts)

            eq = keep_better(eq, load_continuation(solve, q0))
        step = order_step(scene)
        if step is not None and not bool(np.all(eq.converged)):
            retry = order_continuation(
                step,
                lambda start: solve_equilibrium(
                    step.scene, controls, start, fallback=False, **options
                ),
                lambda start: _solve(scene, controls, jnp.asarray(start, dtype), opts),
                np.asarray(q0),
            )
            eq = keep_better(eq, retry)
        if fallback and not bool(np.all(eq.converged)):
            eq = keep_better(
                eq, _solve(scene, controls, q0, dataclasses.replace(opts, method="flow"))
            )
    return eq


def _is_traced(x) -> bool:
    return isinstance(x, jax.core.Tracer)
