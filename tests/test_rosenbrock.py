"""The Rosenbrock-W solver (``pacjax._dynamics.rosenbrock``) and the Jacobian of the dynamics'
stiff part it is given by default (``EquationsOfMotion.stiff_jacobian``)."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from dynamics_scenes import CONTROLS, SCENE, small_scene
from jax.flatten_util import ravel_pytree
from marks import slow

import pacjax as pj
from pacjax._dynamics.equations import (
    EquationsOfMotion,
    plane_angle_weights,
    vector_field,
    vector_field_jacobian,
)
from pacjax._dynamics.rosenbrock import Rosenbrock23, secant_update
from pacjax._dynamics.simulate import step_loop
from pacjax._model.inertia import mass_matrix
from pacjax._model.inputs import as_traced_leaves

A = jnp.array([[-1.0, 2.0], [-3.0, -50.0]])


def _forced_linear(t, y, args):
    return A @ y + jnp.array([jnp.sin(3.0 * t), 0.0])


def _end_error(jacobian, n_steps: int, reference) -> float:
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_forced_linear),
        Rosenbrock23(jacobian=jacobian),
        0.0,
        1.0,
        1.0 / n_steps,
        jnp.array([1.0, 1.0]),
        stepsize_controller=diffrax.ConstantStepSize(),
    )
    return float(jnp.max(jnp.abs(sol.ys[-1] - reference)))


@pytest.mark.parametrize(
    "jacobian",
    [
        None,
        slow("differences"),
        slow(lambda t, y, args: 0.8 * A),
        lambda t, y, args: jnp.diag(jnp.diag(A)),
    ],
    ids=["exact", "differences", "scaled", "diagonal"],
)
def test_second_order_with_any_jacobian(jacobian):
    """A W-method: halving the step quarters the error whatever matrix stands in for the
    Jacobian (a non-autonomous problem, so the time derivative term counts too)."""
    reference = diffrax.diffeqsolve(
        diffrax.ODETerm(_forced_linear),
        diffrax.Kvaerno5(),
        0.0,
        1.0,
        1e-3,
        jnp.array([1.0, 1.0]),
        stepsize_controller=diffrax.PIDController(rtol=1e-12, atol=1e-14),
        max_steps=100_000,
    ).ys[-1]
    errors = np.array([_end_error(jacobian, n, reference) for n in (40, 80, 160, 320)])
    orders = np.log2(errors[:-1] / errors[1:])
    np.testing.assert_allclose(orders, 2.0, atol=0.1)


def _van_der_pol(t, y, mu):
    x, v = y
    return v, mu * (1 - x**2) * v - x


def _van_der_pol_end(solver, mu=50.0, t1=100.0, rtol=1e-6):
    return diffrax.diffeqsolve(
        diffrax.ODETerm(_van_der_pol),
        solver,
        0.0,
        t1,
        None,
        (jnp.array(2.0), jnp.array(0.0)),
        args=mu,
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=rtol * 1e-2),
        max_steps=100_000,
    )


@pytest.mark.slow  # two adaptive integrations of thousands of steps (13 s): CI's slow step
def test_stiff_van_der_pol_matches_kvaerno5():
    """mu = 1000: L-stable steps through the fast transitions, dense output between them; the
    same steps with ``autonomous=True``."""

    ts = jnp.linspace(0.0, 3000.0, 7)
    ys = {}
    solvers = (
        ("ros", Rosenbrock23()),
        ("ros_autonomous", Rosenbrock23(autonomous=True)),
        ("ros_differences", Rosenbrock23(jacobian="differences", reuse=5)),
        ("kv5", diffrax.Kvaerno5()),
    )
    for name, solver in solvers:
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(_van_der_pol),
            solver,
            0.0,
            3000.0,
            None,
            (jnp.array(2.0), jnp.array(0.0)),
            args=1000.0,
            saveat=diffrax.SaveAt(ts=ts, dense=True),
            stepsize_controller=diffrax.PIDController(rtol=1e-6, atol=1e-8),
            max_steps=100_000,
        )
        assert sol.result == diffrax.RESULTS.successful
        ys[name] = (sol.ys[0], jax.vmap(sol.evaluate)(ts + 0.5)[0])
    np.testing.assert_allclose(ys["ros"][0], ys["kv5"][0], atol=2e-4)
    np.testing.assert_allclose(ys["ros"][1], ys["kv5"][1], atol=2e-4)
    np.testing.assert_allclose(ys["ros_differences"][0], ys["kv5"][0], atol=2e-4)
    np.testing.assert_allclose(ys["ros_differences"][1], ys["kv5"][1], atol=2e-4)
    # The problem is autonomous: leaving out T (exactly zero) changes no step.
    np.testing.assert_array_equal(ys["ros_autonomous"][0], ys["ros"][0])
    np.testing.assert_array_equal(ys["ros_autonomous"][1], ys["ros"][1])


def test_held_jacobian_serves_several_steps():
    """``reuse=5``: a Jacobian is made once per five accepted steps (counted as it is made, with
    the retries after rejected steps), and the motion is the same to the tolerance."""
    made = {1: 0, 5: 0}

    def counted(reuse):
        def jacobian(t, y, mu):
            def count():
                made[reuse] += 1

            jax.debug.callback(count)
            x, v = y
            return jnp.array([[0.0, 1.0], [-2.0 * mu * x * v - 1.0, mu * (1 - x**2)]])

        return jacobian

    sols = {r: _van_der_pol_end(Rosenbrock23(jacobian=counted(r), reuse=r)) for r in (1, 5)}
    for sol in sols.values():
        assert sol.result == diffrax.RESULTS.successful
    assert made[1] == int(sols[1].stats["num_steps"])
    accepted, steps = int(sols[5].stats["num_accepted_steps"]), int(sols[5].stats["num_steps"])
    assert accepted / 5 <= made[5] <= accepted / 5 + (steps - accepted) + 1
    np.testing.assert_allclose(sols[5].ys[0], sols[1].ys[0], atol=1e-3)
    with pytest.raises(ValueError, match="reuse"):
        Rosenbrock23(reuse=0)
    with pytest.raises(ValueError, match="jacobian"):
        Rosenbrock23(jacobian="finite")


def test_rows_under_vmap_make_their_held_jacobian_together():
    """Rows of a ``vmap``-ped solve (three stiffnesses, ``reuse=5``) make one Jacobian, all
    together, when a row still stepping needs one: a choice by each row's own flag would be a
    select that makes it every step. Each row still accepts and rejects its own steps and ends
    where its own solve does, to the tolerance."""
    made = [0]

    def jacobian(t, y, mu):
        jax.debug.callback(lambda: made.__setitem__(0, made[0] + 1))
        x, v = y
        return jnp.array([[0.0, 1.0], [-2.0 * mu * x * v - 1.0, mu * (1 - x**2)]])

    solver = Rosenbrock23(jacobian=jacobian, reuse=5)
    mus = jnp.array([5.0, 20.0, 50.0])
    rows = jax.jit(jax.vmap(lambda mu: _van_der_pol_end(solver, mu, t1=20.0)))(mus)
    assert bool(jnp.all(rows.result == diffrax.RESULTS.successful))
    accepted = np.asarray(rows.stats["num_accepted_steps"])
    steps = np.asarray(rows.stats["num_steps"])
    # Every loop pass makes at most one (made for all rows); one every 5 accepted steps of the
    # row that ages fastest, and after its rejections.
    assert made[0] <= steps.max() / 2
    assert made[0] >= accepted.max() / 5
    for i, mu in enumerate(mus):
        own = _van_der_pol_end(solver, mu, t1=20.0)
        np.testing.assert_allclose(rows.ys[0][i], own.ys[0], atol=1e-4)
        assert abs(int(steps[i]) - int(own.stats["num_steps"])) <= 0.2 * steps[i]


def test_after_a_jump_the_step_starts_from_the_vector_field_there():
    """A solver state carried from another point (here the end of another solve) with
    ``made_jump=True``, as after a jump in the vector field: the step evaluates the vector field
    at its start again rather than take the carried one, with the Jacobian made every step or
    held, and equals a step from a fresh state."""
    term = diffrax.ODETerm(_forced_linear)
    y0 = jnp.array([1.0, 1.0])

    @eqx.filter_jit  # one program per solver (one step): the span, state and jump are traced
    def solve(solver, y, t1, state, made_jump):
        return diffrax.diffeqsolve(
            term,
            solver,
            0.0,
            t1,
            t1,
            y,
            stepsize_controller=diffrax.ConstantStepSize(),
            saveat=diffrax.SaveAt(t1=True, solver_state=True),
            solver_state=state,
            made_jump=made_jump,
        )

    for solver in (Rosenbrock23(), Rosenbrock23(jacobian="differences", reuse=5)):

        def end(state, made_jump, solver=solver):
            return solve(solver, y0, 0.15, state, jnp.asarray(made_jump)).ys[-1]

        start = solver.init(term, 0.0, 0.15, y0, None)
        fresh = end(start, False)
        elsewhere = solve(solver, 3.0 * y0, 0.3, solver.init(term, 0.0, 0.3, 3.0 * y0, None), False)
        np.testing.assert_allclose(end(elsewhere.solver_state, True), fresh, rtol=1e-12)
        stale = end(elsewhere.solver_state, False)
        assert float(jnp.max(jnp.abs(stale - fresh))) > 1e-3  # the carried one is stale


def test_secant_correction_maps_the_step_and_keeps_the_rest():
    rng = np.random.default_rng(0)
    jac, dy, df = rng.normal(size=(4, 4)), rng.normal(size=4), rng.normal(size=4)
    corrected = secant_update(jnp.asarray(jac), jnp.asarray(dy), jnp.asarray(df))
    np.testing.assert_allclose(corrected @ dy, df, rtol=1e-13, atol=1e-13)
    across = np.linalg.svd(dy[None])[2][1:]  # directions orthogonal to the step
    np.testing.assert_allclose(corrected @ across.T, jac @ across.T, rtol=1e-13, atol=1e-13)
    unmoved = secant_update(jnp.asarray(jac), jnp.zeros(4), jnp.asarray(df))
    np.testing.assert_array_equal(unmoved, jac)


def test_secant_correction_lets_a_held_jacobian_take_longer_steps():
    """A Jacobian held for 20 steps, with and without the correction along each step: the same
    motion, and the correction saves steps (the error estimate of a stale ``J`` is larger)."""
    sols = {
        secant: _van_der_pol_end(
            Rosenbrock23(jacobian="differences", reuse=20, secant=secant), mu=1000.0, t1=3000.0
        )
        for secant in (False, True)
    }
    for sol in sols.values():
        assert sol.result == diffrax.RESULTS.successful
    np.testing.assert_allclose(sols[True].ys[0], sols[False].ys[0], atol=1e-3)
    steps = {k: int(sol.stats["num_steps"]) for k, sol in sols.items()}
    assert steps[True] < steps[False], steps


def test_error_weight_scales_the_error_estimate():
    """A zero weight on the fast velocity leaves the step size to the position alone: fewer
    steps, the position still to the tolerance."""
    plain = _van_der_pol_end(Rosenbrock23())
    weighted = _van_der_pol_end(
        Rosenbrock23(error_weight=lambda y, mu: (jnp.ones_like(y[0]), jnp.zeros_like(y[1])))
    )
    assert int(weighted.stats["num_steps"]) < int(plain.stats["num_steps"])
    np.testing.assert_allclose(weighted.ys[0], plain.ys[0], atol=1e-3)


def test_gradient_through_adaptive_steps_matches_finite_differences():
    """Reverse mode through Rosenbrock23's adaptive steps (``W`` is held out of the derivative:
    a W-method's solution does not depend on its matrix to the order of the method) equals central
    differences of the solve: van der Pol, mu = 20, ``x(2)`` against mu (6e-8 apart, the
    differences' own error at this step)."""

    def end(mu):
        return _van_der_pol_end(Rosenbrock23(), mu, t1=2.0, rtol=1e-8).ys[0][-1]

    mu, h = jnp.asarray(20.0), 1e-5
    grad = float(jax.grad(end)(mu))
    fd = float((end(mu + h) - end(mu - h)) / (2 * h))
    assert abs(fd) > 1e-3
    assert abs(grad - fd) < 1e-6 * abs(fd)


def test_each_form_of_the_step_loop_solves_and_differentiates_alike():
    """The step's loop of vector fields as a checkpointed while loop (reverse mode), a plain one
    (forward mode) and a scan over every pass (either): the same steps, and the same derivative
    of ``x(2)`` in mu by the first in reverse mode and the second in forward mode (van der Pol,
    mu = 20, differences made every fifth step, so that the loops skip the differences' passes
    between)."""

    def end(mu, loop, adjoint):
        return diffrax.diffeqsolve(
            diffrax.ODETerm(_van_der_pol),
            Rosenbrock23(jacobian="differences", reuse=5, loop=loop),
            0.0,
            2.0,
            None,
            (jnp.array(2.0), jnp.array(0.0)),
            args=mu,
            stepsize_controller=diffrax.PIDController(rtol=1e-6, atol=1e-8),
            adjoint=adjoint,
        )

    mu = jnp.asarray(20.0)
    reverse, forward = diffrax.RecursiveCheckpointAdjoint(), diffrax.ForwardMode()
    sols = {loop: end(mu, loop, reverse) for loop in ("checkpointed", "lax", "scan")}
    for sol in sols.values():
        assert sol.result == diffrax.RESULTS.successful
        assert int(sol.stats["num_steps"]) == int(sols["scan"].stats["num_steps"]) > 10
        np.testing.assert_allclose(sol.ys[0], sols["scan"].ys[0], rtol=1e-12)
    backward = float(jax.grad(lambda m: end(m, "checkpointed", reverse).ys[0][-1])(mu))
    onward = float(jax.jacfwd(lambda m: end(m, "lax", forward).ys[0][-1])(mu))
    assert abs(backward) > 1e-3
    assert onward == pytest.approx(backward, rel=1e-10)
    with pytest.raises(ValueError, match="loop"):
        Rosenbrock23(loop="while")
    assert step_loop(reverse) == "checkpointed"
    assert step_loop(forward) == "lax"
    assert step_loop(diffrax.DirectAdjoint()) == "scan"


def test_solving_traces_the_vector_field_once():
    """A jitted vector field is traced once per solve: diffrax's check of the term, the
    solver's state and its steps all call it alike (a Python float in ``args`` is static to
    the ``jit``, so a shape evaluation that made it abstract would trace it anew)."""
    traces = []

    @eqx.filter_jit
    def field(t, y, mu):
        traces.append(1)
        return _van_der_pol(t, y, mu)

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        Rosenbrock23(jacobian="differences", reuse=5),
        0.0,
        1.0,
        None,
        (jnp.array(2.0), jnp.array(0.0)),
        args=20.0,
        stepsize_controller=diffrax.PIDController(rtol=1e-6, atol=1e-8),
    )
    assert sol.result == diffrax.RESULTS.successful
    assert len(traces) == 1


@pytest.mark.slow  # jax.jacfwd of the whole vector field compiles for tens of seconds
def test_differences_make_the_vector_fields_jacobian():
    """The exact Jacobian that the solver makes by forward differences, in its loop of vector
    fields, and holds equals ``jax.jacfwd`` of the vector field, in motion with the tendons taut,
    to the differences' truncation (a few 1e-5 of the largest entries, the tendon springs'): on
    the first step, where the loop evaluates the start's vector field too, and on the sixth
    (``reuse=5``), where that is carried from the step before."""
    scene = as_traced_leaves(SCENE, jnp.float64)
    model = EquationsOfMotion.build(scene, pj.Damping.modal(SCENE), 1e-6, jnp.float64)
    n = scene.n_dofs
    y = (jnp.linspace(0.2, -0.3, n).at[-1].set(-0.002), jnp.linspace(-1.0, 2.0, n))
    args = (model, CONTROLS + 0.004)
    solver = Rosenbrock23(jacobian="differences", reuse=5, secant=False, autonomous=True)
    x0, unravel = ravel_pytree(y)
    dt = 1e-6

    @jax.jit
    def made_and_exact(steps):
        # The state where the last step began, and the Jacobian held after it (made there).
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(vector_field),
            solver,
            0.0,
            steps * dt,
            dt,
            y,
            args,
            stepsize_controller=diffrax.ConstantStepSize(),
            saveat=diffrax.SaveAt(ts=[(steps - 1) * dt], solver_state=True),
        )
        start = ravel_pytree(jax.tree.map(lambda leaf: leaf[0], sol.ys))[0]
        exact = jax.jacfwd(lambda x: ravel_pytree(vector_field(0.0, unravel(x), args))[0])(start)
        return sol.solver_state[1], exact

    for steps in (1, 6):
        made, exact = made_and_exact(steps)
        scale = float(jnp.abs(exact).max())
        np.testing.assert_allclose(made, exact, rtol=1e-4, atol=1e-6 * scale)


def test_plane_angle_weights_follow_the_bends():
    """PAC: a straight segment's ``phi`` weighs nothing, a segment bent by 0.3 rad 0.3, an S
    (no bend at its end) its bend at the middle, one bent past a radian 1; every other
    coordinate and the velocities' likewise; Cartesian models weigh all ones."""
    length = 0.1
    segments = [pj.Segment(length, 0.02, 600.0, linear_density=0.3)] * 4
    scene = pj.Scene(pj.Robot(segments), pj.PAC())
    model = EquationsOfMotion.build(scene, pj.Damping(), 1e-6, jnp.float64)
    a = 2.0
    coords = jnp.array(
        [
            [0.0, 0.0, 1.3, 0.0],
            [0.3 / length, 0.0, 0.4, 1e-3],
            [a, -2 * a / length, -2.0, 0.0],
            [20.0, 0.0, 0.1, 0.0],
        ]
    )
    q = scene.free_part(coords)
    wq, wv = plane_angle_weights((q, q), (model, None))
    expected = jnp.ones_like(coords).at[:, 2].set(jnp.array([0.0, 0.3, a * length / 4, 1.0]))
    np.testing.assert_allclose(wq, scene.free_part(expected), rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(wv, wq)
    cartesian = pj.Scene(pj.Robot(segments), pj.PolynomialCurvature(1))
    model = EquationsOfMotion.build(cartesian, pj.Damping(), 1e-6, jnp.float64)
    q = jnp.ones(cartesian.n_dofs)
    np.testing.assert_array_equal(plane_angle_weights((q, q), (model, None))[0], jnp.ones_like(q))


@pytest.mark.slow  # the reference compiles the forces' plain Hessian (16 s)
def test_stiff_jacobian_is_the_forces_derivative_while_moving():
    """In motion, with the tendons taut and stretching (their motors' damping pulling), the
    Jacobian's acceleration rows are ``M^-1 dF`` of every force but inertia's, ``M`` held: the
    structured Hessian with the motors' whole tension as springs, plus the damping's
    derivatives, equals ``jax.jacfwd`` of the forces but for the one term it leaves out, the
    motors' damping through the change of the tendons' Jacobian, ``J^T kappa_D (dJ/dq qdot)``."""
    scene = as_traced_leaves(SCENE, jnp.float64)
    model = EquationsOfMotion.build(scene, pj.Damping.modal(SCENE), 1e-6, jnp.float64)
    n = scene.n_dofs
    q = jnp.linspace(0.2, -0.3, n).at[-1].set(-0.002)
    qdot = jnp.linspace(-1.0, 2.0, n)
    slack = scene.rest_tendon_lengths() - scene.tendon_lengths(q)
    u, udot = jnp.maximum(slack, 0.0) + jnp.array([0.004, 0.002]), jnp.array([0.05, -0.01])

    stiff_jacobian = jax.jit(lambda q, qdot: model.stiff_jacobian(q, qdot, u, udot))

    @jax.jit
    def reference(q, qdot):
        held = mass_matrix(scene, q)

        def forces(x, v):
            return model.forces(x, v, u, udot, held)

        d_q, d_v = jax.jacfwd(forces, argnums=(0, 1))(q, qdot)
        jac = jax.jacfwd(scene.tendon_lengths)(q)
        rate_jac = jax.jacfwd(lambda x: jax.jvp(scene.tendon_lengths, (x,), (qdot,))[1])(q)
        d_q = d_q + (jac.T * model.tendon_damping) @ rate_jac  # both taut: the gains are kappa_D
        return jnp.linalg.solve(held, jnp.concatenate([d_q, d_v], axis=1))

    stiff, ref = stiff_jacobian(q, qdot)[n:], reference(q, qdot)
    scale = float(jnp.abs(ref).max())
    np.testing.assert_allclose(stiff, ref, rtol=1e-9, atol=1e-10 * scale)


@pytest.mark.slow  # the exact Jacobian compiles the kinematics' third derivatives
def test_stiff_jacobian_is_exact_where_the_inertia_is_still():
    """At rest in an equilibrium (no Coriolis forces, whose derivative in ``qdot`` vanishes
    there, and no net force for the mass matrix's derivative to act on), freezing the inertia
    leaves nothing out: the Jacobian equals the vector field's own. At rest anywhere, its
    velocity columns do (the Coriolis forces are quadratic in ``qdot``). On the smallest scene
    with every force the Jacobian holds (45 s on 2 cores; the shared linear-curvature scene's
    exact Jacobian took 140 s)."""
    tiny = small_scene(order=0, quadrature_points=2)
    scene = as_traced_leaves(tiny, jnp.float64)
    eq = pj.solve_equilibrium(tiny, CONTROLS, tol=1e-12)
    model = EquationsOfMotion.build(scene, pj.Damping.modal(tiny), 1e-6, jnp.float64)
    args = (model, CONTROLS)
    n = scene.n_dofs

    @jax.jit
    def exact(q, qdot):
        flat = jnp.concatenate([q, qdot])
        return jax.jacfwd(lambda x: jnp.concatenate(vector_field(0.0, (x[:n], x[n:]), args)))(flat)

    frozen_jacobian = jax.jit(lambda q, qdot: vector_field_jacobian(0.0, (q, qdot), args))
    rest = jnp.zeros_like(eq.q)
    frozen = frozen_jacobian(eq.q, rest)
    scale = float(jnp.abs(frozen).max())
    np.testing.assert_allclose(frozen, exact(eq.q, rest), rtol=1e-8, atol=1e-9 * scale)
    bent = eq.q + 0.05
    np.testing.assert_allclose(
        frozen_jacobian(bent, rest)[:, n:],
        exact(bent, rest)[:, n:],
        rtol=1e-8,
        atol=1e-9 * scale,
    )


@pytest.mark.long(minutes=1.2)
@pytest.mark.slow
def test_simulate_with_rosenbrock_matches_a_tight_reference():
    """A step of the tendon commands from rest, 0.1 s: Rosenbrock23 at rtol 1e-6 against an
    explicit solver at 1e-9 (the scene's fastest mode is 55 Hz, not stiff; Kvaerno5 as the
    reference took 2.5 min on 2 cores, nearly all compiling)."""
    start = pj.solve_equilibrium(SCENE, jnp.zeros(2), tol=1e-12)
    runs = {}
    reference = ("ref", diffrax.Tsit5(), 1e-9)
    for name, solver, rtol in (("ros", pj.dynamics.rosenbrock23(), 1e-6), reference):
        runs[name] = pj.simulate(
            SCENE,
            (0.0, 0.1),
            CONTROLS,
            q0=start.q,
            saveat=[0.05, 0.1],
            solver=solver,
            rtol=rtol,
            atol=rtol * 1e-2,
        )
        assert bool(runs[name].successful)
    tips = {
        k: np.asarray(jax.vmap(lambda q: pj.tip_pose(SCENE, q)[0])(r.q)) for k, r in runs.items()
    }
    assert np.max(np.abs(tips["ros"] - tips["ref"])) < 1e-5  # m
    assert np.max(np.abs(tips["ref"][0] - pj.tip_pose(SCENE, start.q)[0])) > 1e-3  # it moved
