"""Dynamics: the paper's full model (its eq. 7, :mod:`pacjax._dynamics.equations`) integrated with
diffrax.

The state ``(q, qdot)`` is integrated with adaptive steps (PID controller) by a stiff solver:
the tendon springs, the axial stiffness and the stiffness-proportional damping are fast against
the soft body's motion. At moderate tolerances (``rtol >= 1e-5``) the default is
:class:`pacjax._dynamics.rosenbrock.Rosenbrock23`, a linearly implicit W-method
(:func:`rosenbrock23`), with the vector field's exact Jacobian (by differences) made once per
several steps: the inertia's own derivatives, which the forces' Jacobian leaves out, are fast
where PCC/PAC's plane angle swings round a segment passing near straight, and without them the
steps there were several times shorter. Its error estimate weighs each plane angle by its
segment's bend (the body's motion, not the coordinate's). At tight tolerances it is
``diffrax.Kvaerno5`` (L-stable, 5th order), whose
stage equations are solved by diffrax's chord method with the Jacobian taken in forward mode
(:class:`pacjax._chord.DenseChord`). The vector field takes the model and controls as
arguments, not by closure, so that its trace and its derivatives' are made once. Gradients of a
trajectory with respect to any scene or damping parameter, the initial state or the controls go
through diffrax's checkpointed adjoint.
"""

import dataclasses

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .. import _deprecated
from .._chord import kvaerno5
from .._jit import jit
from .._model.inertia import PHI_INERTIA_FACTOR
from .._model.inputs import (
    as_traced_leaves,
    check_controls,
    check_q,
    check_scene,
    frozen,
    solver_dtype,
    static_load_sites,
)
from .._model.kinematics import DEFAULT_KNOT_GRID
from .._model.scene import Scene
from .._model.strain import PlanarCurvature
from .._model.values import concrete
from .._results import RESULTS
from .._statics.problem import ScaledProblem
from .damping import Damping
from .equations import (
    EquationsOfMotion,
    plane_angle_weights,
    vector_field,
    vector_field_jacobian,
)
from .rosenbrock import Rosenbrock23

__all__ = [
    "Trajectory",
    "simulate",
    "rosenbrock23",
    "ROSENBROCK_RTOL",
    "KNOT_GRID",
    "JACOBIAN_REUSE",
    "default_solver",
]


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


#: :func:`simulate`'s default relative tolerance: what control, learning and animation need,
#: and where the default solver, :func:`rosenbrock23`, is at its best; the paper's robot's tip
#: then follows a reference a thousand times tighter to well under a tenth of a millimetre
#: (``benchmarks/bench_dynamics.py``). A reference solution asks for ``rtol < ROSENBROCK_RTOL``.
RTOL = 1e-4
#: :func:`simulate`'s default absolute tolerance, in the state's SI units (m, rad, per second).
ATOL = 1e-6


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
    rtol: float = RTOL,
    atol: float = ATOL,
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
            linearly implicit method, the exact Jacobian made once per several steps: cheap
            steps for control and learning); tighter, ``diffrax.Kvaerno5`` with
            :class:`pacjax._chord.DenseChord` (diffrax's chord method with a forward-mode
            Jacobian). A non-stiff solver such as ``diffrax.Tsit5()`` only suits scenes without
            stiff tendons or damping.
        rtol, atol: tolerances of the adaptive step size (``atol`` in the state's SI units).
            The defaults, :data:`RTOL` and :data:`ATOL`, take :func:`rosenbrock23`; pass
            ``rtol < 1e-5`` for a reference solution (Kvaerno5, many times slower).
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
    dt0 = check_dt0(dt0, t0, t1, dtype)
    controls = check_simulation_controls(scene, controls, t0, dtype)
    q0 = check_q(scene, q0, dtype)
    qdot0 = check_qdot(scene, qdot0, dtype)
    scene, damping, opts, span, ts = prepare(
        scene, t0, t1, saveat, damping, solver, rtol, atol, max_steps, dense, phi_inertia, adjoint
    )
    q0 = aligned_rest_start(scene, controls, q0, qdot0, span[0])
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
    scene = _dynamics_scene(static_load_sites(as_traced_leaves(scene, dtype)), rtol)
    damping = _check_damping(scene, damping, dtype)
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


#: The knot grid ``(intervals, nodes)`` (:attr:`pacjax.Scene.knot_grid`) of a simulation at
#: ``rtol >= ROSENBROCK_RTOL`` on a scene of PCC/PAC segments that sets none. The statics'
#: ``(8, 4)`` puts the positions at round-off, far below what a step error of 1e-5 can see;
#: ``(4, 3)`` places the paper's robot's frames within 3e-8 m of it while each segment turns
#: by up to 2 rad, and within 1e-6 m at 4.5 rad (``tests/test_kinematics.py``), with a third
#: less arithmetic in the vector field. ``PolynomialCurvature``, whose rotation is integrated
#: by Magnus steps on the intervals (not in closed form), keeps the statics' intervals and
#: takes the three nodes only. Tighter tolerances (references) keep the scene's grid.
KNOT_GRID = (4, 3)


def _dynamics_scene(scene: Scene, rtol: float) -> Scene:
    """``scene`` as the dynamics evaluate it: PCC/PAC models taking sines and cosines as fused
    arithmetic (:mod:`pacjax._model.trig`), and at the default tolerances a coarser knot grid
    (:data:`KNOT_GRID`) unless the scene sets one. A simulation evaluates its vector field
    thousands of times, so the program's run time counts for more than its compile time."""
    models = tuple(
        m.with_fused_trig() if isinstance(m, PlanarCurvature) else m for m in scene.models
    )
    grid = scene.knot_grid
    if grid is None and rtol >= ROSENBROCK_RTOL:
        closed_form = all(isinstance(m, PlanarCurvature) for m in scene.models)
        grid = KNOT_GRID if closed_form else (DEFAULT_KNOT_GRID[0], KNOT_GRID[1])
    if models == scene.models and grid == scene.knot_grid:
        return scene
    return scene.replace(model=models if scene.segment_models else models[0], knot_grid=grid)


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


def _check_damping(scene: Scene, damping, dtype) -> Damping:
    """The given damping, or the default modal one (5 % on the lowest mode), in the solver's
    precision: a float64 coefficient (``Damping()``'s zero mass term is one) would promote a
    float32 scene's forces to float64, which its float32 mass matrix cannot solve."""
    if damping is None:
        damping = Damping.modal(scene)
    if not isinstance(damping, Damping):
        raise TypeError(f"damping must be a pacjax.Damping, got {type(damping).__name__}")
    if damping.tendon is not None and jnp.ndim(damping.tendon) == 1:
        if damping.tendon.shape != (scene.n_tendons,):
            raise ValueError(
                f"Damping.tendon must have shape ({scene.n_tendons},), got {damping.tendon.shape}"
            )
    return jax.tree.map(lambda x: x.astype(dtype) if eqx.is_inexact_array(x) else x, damping)


@jit(once=True)  # run once per simulation (pacjax._jit)
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


def check_dt0(dt0, t0: float, t1: float, dtype):
    """``dt0`` as an array of ``dtype`` (None stays None): a first step in ``(0, t1 - t0]``."""
    if dt0 is None:
        return None
    step = np.asarray(dt0, dtype=float)
    if step.shape != () or not (0.0 < float(step) <= t1 - t0):
        raise ValueError(f"dt0 must be a first step in (0, t1 - t0 = {t1 - t0:g}] s, got {dt0!r}")
    return jnp.asarray(step, dtype)


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


#: Accepted steps one exact Jacobian serves in :func:`rosenbrock23`'s default.
JACOBIAN_REUSE = 20


def rosenbrock23(jacobian: str = "exact", reuse: int | None = None) -> Rosenbrock23:
    """:class:`Rosenbrock23` for the dynamics: :func:`simulate`'s solver at moderate tolerances.

    Args:
        jacobian: ``"exact"``: the vector field's Jacobian by forward differences
            (:class:`Rosenbrock23`'s ``"differences"``), one per ``reuse``
            accepted steps (default :data:`JACOBIAN_REUSE`), corrected along each step between
            them (Broyden's update, :class:`Rosenbrock23`'s ``secant``): dear (a vector field
            per state coordinate) but it holds the inertia's fast part, so the steps are several
            times fewer. In a ``vmap``-ped group of rows the rows make it together when one
            needs it (:mod:`pacjax._dynamics.rosenbrock`). ``"stiff"``:
            :meth:`EquationsOfMotion.stiff_jacobian`, the forces' derivatives with the inertia
            held, cheap enough to make every step (default ``reuse=1``), but it leaves out the
            inertia's fast part, so the steps are several times more.
        reuse: accepted steps one Jacobian serves.

    Either way the plane angles' errors are weighted by their segments' bends
    (:func:`pacjax._dynamics.equations.plane_angle_weights`).
    """
    if jacobian == "exact":
        function, default_reuse = "differences", JACOBIAN_REUSE
    elif jacobian == "stiff":
        function, default_reuse = vector_field_jacobian, 1
    else:
        raise ValueError(f'jacobian must be "exact" or "stiff", got {jacobian!r}')
    return Rosenbrock23(
        jacobian=function,
        reuse=default_reuse if reuse is None else reuse,
        error_weight=plane_angle_weights,
    )


#: ``rtol`` from which :func:`simulate` takes :func:`rosenbrock23` by default (Kvaerno5 below).
ROSENBROCK_RTOL = 1e-5


def default_solver(rtol: float) -> diffrax.AbstractSolver:
    """From ``rtol >= ROSENBROCK_RTOL``, :func:`rosenbrock23` with its held exact Jacobian (a
    row alone or rows in a ``vmap``-ped group): one factorisation and two vector fields a step;
    below it Kvaerno5 with :class:`pacjax._chord.DenseChord`, whose fifth order takes fewer
    (dearer) steps to a tight tolerance."""
    if rtol < ROSENBROCK_RTOL:
        return kvaerno5()
    return rosenbrock23()


#: The vector field as the integration traces it: diffrax and the solvers call it several
#: times while tracing one program (the first step's size, the state's shape, the stages, the
#: Jacobian's differences), and a ``jit`` traces the Python once for all calls alike; XLA
#: inlines it, so the compiled program is the same.
_TRACED_VECTOR_FIELD = eqx.filter_jit(vector_field)


def step_loop(adjoint) -> str:
    """:class:`Rosenbrock23`'s ``loop`` for a diffrax adjoint: diffrax's checkpointed one
    differentiates each step in reverse mode, ``ForwardMode`` in forward mode (which a
    checkpointed loop does not support), and the others either way."""
    if isinstance(adjoint, diffrax.RecursiveCheckpointAdjoint):
        return "checkpointed"
    if isinstance(adjoint, diffrax.ForwardMode):
        return "lax"
    return "scan"


@eqx.filter_jit
def integrate(scene, damping, controls, q0, qdot0, span, ts, dt0, opts: _Options):
    """The compiled simulation of checked inputs (:func:`prepare`, :func:`aligned_rest_start`):
    one row of :func:`pacjax._dynamics.batch.simulate_batch`."""
    model = EquationsOfMotion.build(scene, damping, opts.phi_inertia, q0.dtype)
    solver = opts.solver
    if isinstance(solver, Rosenbrock23) and not callable(controls):
        # Constant controls: the vector field does not depend on time (no T term to trace).
        solver = dataclasses.replace(solver, autonomous=True)
    if isinstance(solver, Rosenbrock23):
        # The step's loop as the adjoint differentiates it (see Rosenbrock23.loop).
        solver = dataclasses.replace(solver, loop=step_loop(opts.adjoint))
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_TRACED_VECTOR_FIELD),
        solver,
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
