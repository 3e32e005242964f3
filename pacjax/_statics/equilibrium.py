"""Static equilibrium: continuation of the damped flow to a steady state, with stability.

The paper finds equilibria by integrating the damped flow ``D qdot = -F(q)`` to a steady state.
That flow is stiff (tendon gains against a soft body): an explicit integrator needs tens of
thousands of steps. pacjax integrates it with linearised implicit Euler steps whose size grows as
the residual falls (pseudo-transient continuation, :mod:`pacjax._statics.ptc`): far from
equilibrium the
steps follow the flow, near it they are Newton steps with the exact Jacobian, so the last steps
*are* the Newton polish. ``D`` is the diagonal of the elastic stiffness, so the flow is well
scaled. The loop runs inside ``optimistix.root_find``, not differentiated: derivatives of the
equilibrium with respect to any scene parameter or control come from the implicit function
theorem with the continuation's last Jacobian (:mod:`pacjax._statics.implicit`: one directional
derivative of the residual and one linear solve), never from differentiating the iterations.

``method="flow"`` first integrates the preconditioned flow with ``diffrax`` (an adaptive implicit
Runge-Kutta method, stopped by a steady-state event) and then continues from there: slower, and
the automatic fallback when continuation from the given start fails.

An equilibrium that is a saddle (a column past buckling; PAC's straight state where ``phi`` is
undefined) is detected from the smallest eigenvalue of the scaled stiffness and, by default, left
along its direction of negative curvature.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
import optimistix as optx

from .._jit import jit
from .._model.channels import ring_chord_sag
from .._model.inputs import (
    as_traced_leaves,
    check_controls,
    check_q,
    check_scene,
    frozen,
    solver_dtype,
    static_load_sites,
)
from .._model.scene import Scene
from .._results import CONVERGED_SADDLE, from_code
from .continuation import conservative_part, retry_failed
from .implicit import implicit_equilibrium
from .modes import max_abs
from .options import SolverOptions, initial_dt, resolve_options
from .problem import ScaledProblem, flow_field
from .ptc import PseudoTransientContinuation
from .ptc_state import final_code
from .ringcheck import check_rows, warn_sparse_rings
from .solution import Equilibrium


def _flow_start(problem: ScaledProblem, y0, opts: SolverOptions):
    """Integrate the preconditioned flow ``dy/dt = -r(y)`` with diffrax towards a steady state."""
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(flow_field),
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


def make_solver(
    scene: Scene, opts: SolverOptions, dtype, ahead: bool = False
) -> PseudoTransientContinuation:
    """The continuation root finder for a scene's structure and the solver options (their
    tolerance resolved: :func:`solve_core_linearised` and :func:`pacjax.solve_batch` do it).
    ``ahead``: each step tries the next one ahead (the batch's pool; see
    :class:`pacjax._statics.ptc.PseudoTransientContinuation`)."""
    return PseudoTransientContinuation(
        rtol=0.0,
        atol=opts.tol,
        initial_dt=initial_dt(opts, scene.model.newton_from_start()),
        max_dt=opts.max_dt,
        escapes=opts.escapes,
        escape_size=opts.escape_size,
        stability_tol=_stability_tol(opts, dtype),
        symmetric=scene.is_conservative,
        frozen_work=not scene.is_conservative,
        structured=opts.hessian == "structured",
        newton_start=scene.model.newton_from_start(),
        ahead=ahead,
    )


def max_total_steps(opts: SolverOptions) -> int:
    """Continuation steps allowed in all (``max_steps`` per escape attempt)."""
    return opts.max_steps * (1 + opts.escapes)


def start_point(problem: "ScaledProblem", q0, opts: SolverOptions):
    """Scaled starting point ``y0 = q0 / sigma``, its straight segments' bending planes turned
    to the force (:meth:`ScaledProblem.aligned`); no derivative flows through the start."""
    problem = frozen(problem)
    return problem.aligned(jax.lax.stop_gradient(q0) / problem.sigma, opts.tol)


def equilibrium_from(
    scene: Scene, problem: "ScaledProblem", solver, y, state, steps, tol: float
) -> Equilibrium:
    """The :class:`Equilibrium` at the continuation's final iterate ``y`` and state (or at the
    step tried ahead of it, where that ended the solve: ``solver.finish``)."""
    y, residual, merit = solver.finish(y, state)
    residual_norm = max_abs(residual)
    converged = residual_norm <= tol
    stable = state.eig > -solver.stability_tol
    energy = merit if scene.is_conservative else jnp.asarray(jnp.nan, merit.dtype)
    # A stationary point that is not a minimum is not a success: a user who reads only the
    # result must not take a physically impossible shape.
    code = jnp.where(converged & ~stable, CONVERGED_SADDLE, final_code(state, converged))
    return Equilibrium(
        q=jax.lax.stop_gradient(problem.sigma) * y,
        converged=converged,
        residual_norm=residual_norm,
        stable=stable,
        min_hessian_eigenvalue=state.eig,
        steps=steps,
        result=from_code(code),
        energy=energy,
    )


def solve_core(scene: Scene, controls, q0, opts: SolverOptions) -> Equilibrium:
    """One equilibrium (traceable; :func:`solve_equilibrium` and the batch solver wrap it)."""
    return solve_core_linearised(scene, controls, q0, opts)[0]


def solve_core_linearised(scene: Scene, controls, q0, opts: SolverOptions):
    """:func:`solve_core`, and the Jacobian ``dr/dy`` of the scaled residual at the solution
    from the continuation's last linearisation, with the scaling (``y = q / sigma``,
    ``r = row * F``): ``(equilibrium, (jacobian, sigma, row))``, no derivative flowing through
    the last three."""
    opts = resolve_options(opts, q0.dtype)  # the precision's default tolerance
    # The solve itself is not differentiated: the derivative of q comes from the implicit
    # function theorem with the continuation's last Jacobian (implicit_equilibrium).
    problem = ScaledProblem.build(*frozen((scene, controls)))
    y0 = start_point(problem, q0, opts)
    flow_steps = jnp.asarray(0)
    if opts.method == "flow":
        y0, flow_steps = _flow_start(problem, y0, opts)
    solver = make_solver(scene, opts, q0.dtype)
    sol = optx.root_find(
        ScaledProblem.root_fn,
        solver,
        y0,
        args=problem,
        has_aux=True,
        max_steps=max_total_steps(opts),
        throw=False,
    )
    steps = sol.stats["num_steps"] + flow_steps
    eq = equilibrium_from(scene, problem, solver, sol.value, sol.state, steps, opts.tol)
    linearised = jax.lax.stop_gradient((sol.state.jacobian, problem.sigma, problem.row))
    q = implicit_equilibrium(scene, controls, eq.q, *linearised)
    return eqx.tree_at(lambda e: e.q, eq, q), linearised


def _solve_and_sag(scene: Scene, controls, q0, opts: SolverOptions):
    """:func:`solve_core` and the ring chords' sag at the solution, in one program: a second
    compiled call per solve would cost a warm single solve a noticeable fraction of its time."""
    eq = solve_core(scene, controls, q0, opts)
    return eq, ring_chord_sag(scene, eq.q)


_solve_checked = jit(_solve_and_sag)
_solve_linearised = jit(solve_core_linearised)


def linearised_equilibrium(scene: Scene, controls, q0, options: SolverOptions):
    """:func:`solve_equilibrium` without retries, traceable (the inverse solver calls it inside
    its least-squares program), and the scaled Jacobian at the solution with its scaling
    (:func:`solve_core_linearised`), the one the implicit derivative of ``q`` uses."""
    return _solve_linearised(*_prepared(scene, controls, q0), options)


def _prepared(scene: Scene, controls, q0):
    """The scene's leaves ready for ``jit`` (:func:`as_traced_leaves`, known load sites static),
    the controls and the start checked against it, in the scene's dtype."""
    dtype = solver_dtype(scene)
    scene = static_load_sites(as_traced_leaves(scene, dtype))
    return scene, check_controls(scene, controls, dtype), check_q(scene, q0, dtype)


def solve_equilibrium(
    scene: Scene,
    controls=None,
    q0=None,
    *,
    fallback: bool = True,
    options: SolverOptions | None = None,
    **overrides,
) -> Equilibrium:
    """Static equilibrium of ``scene`` under ``controls`` (one per tendon), starting from ``q0``.

    Args:
        scene: the :class:`Scene`.
        controls: (n_tendons,) pull-in (m) for length-mode tendons, tension (N) for tension-mode
            ones; default zeros.
        q0: starting configuration (default :meth:`Scene.rest_configuration`: straight
            unless a segment has a rest curvature). A straight PCC/PAC segment's
            bending-plane angle is first turned to the force on it (:meth:`ScaledProblem.aligned`).
        fallback: when continuation fails, retry with the diffrax flow (outside jit, compiled
            only when needed). Whatever ``fallback`` says, a failed solve is first retried by
            load continuation for a non-conservative scene (follower forces, dead moments; from
            the equilibrium of its conservative part), then, for ``PolynomialCurvature`` of
            order >= 2, by order continuation (from the equilibrium one order lower,
            :func:`order_step`).
        options: :class:`SolverOptions` (default ``SolverOptions()``).
        **overrides: single :class:`SolverOptions` fields replaced in ``options`` (``tol``,
            ``max_steps``, ``escapes``, ...); an unknown name raises a TypeError.

    Returns:
        An :class:`Equilibrium`. Differentiable with respect to the scene's parameters and the
        controls (implicit function theorem); ``jit``/``vmap`` compatible.
    """
    check_scene(scene)
    opts = resolve_options(options, solver_dtype(scene), **overrides)
    scene, controls, q0 = _prepared(scene, controls, q0)
    eq, sag = _solve_checked(scene, controls, q0, opts)
    if opts.method == "ptc" and not _is_traced(eq.converged) and not bool(eq.converged):
        eq = _retry(scene, controls, q0, eq, opts, fallback)
        check_rows(scene, eq.q[None])
    else:
        warn_sparse_rings(scene, sag)
    return eq


def _retry(scene: Scene, controls, q0, eq: Equilibrium, opts: SolverOptions, fallback: bool):
    """A failed single solve retried as a batch of one row
    (:func:`pacjax._statics.continuation.retry_failed`; the flow only with ``fallback``)."""

    def one_row(x):
        return jtu.tree_map(lambda a: jnp.asarray(a)[None], x)

    def solve(rows, starts, options, conservative=False, scene=scene):
        # The first attempt's program, sag check and all: a retry of the same scene and
        # options from another start then compiles nothing (one without the check compiled as
        # long as the first).
        sc = conservative_part(scene) if conservative else scene
        eq, _ = _solve_checked(sc, controls, jnp.asarray(starts[0], q0.dtype), options)
        return one_row(eq)

    starts = np.asarray(q0)[None]
    retried = retry_failed(scene, one_row(eq), starts, solve, opts, flow=fallback)
    return jtu.tree_map(lambda a: a[0], retried)


def _is_traced(x) -> bool:
    return isinstance(x, jax.core.Tracer)
