"""The pseudo-transient continuation root finder on its own, and the follower-force residual."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import pacjax as pj
from pacjax._model.inputs import static_load_sites
from pacjax._results import STALLED
from pacjax._statics.ptc import PseudoTransientContinuation


def test_no_descent_at_the_smallest_step_is_reported_stalled_early():
    # r(y) = y^2 + 1 has no root; |r|^2 has its minimum at y = 0, where r = 1 and the flow
    # direction -r raises |r|^2. The continuation must say it stalled, not creep on to its step
    # limit (it used to run all 300 steps there).
    def fn(y, args):
        r = y**2 + 1.0
        return r, (0.5 * jnp.sum(r * r), jnp.ones_like(y))

    solver = PseudoTransientContinuation(rtol=0.0, atol=1e-10, symmetric=False)
    sol = optx.root_find(fn, solver, jnp.ones(3), has_aux=True, max_steps=300, throw=False)
    assert int(sol.state.code) == STALLED
    assert int(sol.stats["num_steps"]) < 40, int(sol.stats["num_steps"])
    assert np.all(np.abs(np.asarray(sol.value) ** 2 + 1.0) > 0.5)


def test_a_full_step_within_the_energys_rounding_is_taken():
    # An energy whose terms are ~2e3 but whose value at the solution is zero: near the solution
    # its rounding (that of the terms) hides the decrease of a Newton step, and a rise by
    # rounding there says nothing. The step is taken when its predicted decrease is within the
    # rounding of the energy and the elastic-like term |w y|^2; judged on the energy alone, the
    # continuation rejected those steps and ran to its 300-step limit at residual 2.7e-11.
    rng = np.random.default_rng(0)
    m = rng.normal(size=(6, 6))
    a = jnp.asarray(m @ m.T + 6.0 * np.eye(6))
    # The third draw of b: with b drawn right after m (seeds 0-3) the energy test alone also
    # converged, so those cases do not tell the rule's work.
    rng.normal(size=6)
    rng.normal(size=6)
    b = jnp.asarray(rng.normal(size=6)) * 1e3

    def energy(y):
        return 0.5 * y @ (a @ y) - b @ y + 0.25 * jnp.sum(y**4)

    grad = jax.grad(energy)
    ref = optx.root_find(
        lambda y, _: grad(y), optx.Newton(rtol=1e-10, atol=1e-5), jnp.zeros(6, jnp.float64)
    ).value
    offset = -energy(ref)

    def fn(y, args):
        return grad(y), (energy(y) + offset, jnp.ones_like(y))

    solver = PseudoTransientContinuation(rtol=0.0, atol=1e-12, symmetric=True)
    y0 = jnp.zeros(6, jnp.float64)
    sol = optx.root_find(fn, solver, y0, has_aux=True, max_steps=300, throw=False)
    assert sol.result == optx.RESULTS.successful
    assert int(sol.stats["num_steps"]) <= 15, int(sol.stats["num_steps"])
    assert np.abs(np.asarray(grad(sol.value))).max() <= 1e-12


def test_a_follower_loaded_solve_leaves_the_saddle_of_a_straight_segments_plane_angle():
    # A straight PAC segment whose bending-plane angle is pi sits at the maximum of that angle's
    # regulariser k (1 - cos phi): a saddle of the model's energy (scaled eigenvalue -5e-6
    # here). The escape left it, but in a non-conservative scene the next step was the plain
    # Newton step, which converges to the nearest stationary point: the same saddle, reported
    # unstable (a campaign draw, seed 25, whose batch row reached the stable twin).
    seg = pj.Segment(0.1, 0.02, 1e3, 0.1)
    pull = pj.PointForce((0.0, 0.0, 1.0), segment=1, s=1.0, follower=True)
    scene = pj.Scene(pj.Robot([seg, seg]), pj.PAC(), loads=(pull,))
    q0 = np.zeros(scene.n_dofs)
    q0[2::4] = np.pi
    eq = pj.solve_equilibrium(scene, q0=q0, fallback=False)
    assert bool(eq.successful), eq.reason
    assert float(eq.min_hessian_eigenvalue) > 0.0
    np.testing.assert_array_less(0.0, np.cos(np.asarray(eq.q)[2::4]))


def _quadratic_solve(stiffness, load, ahead):
    """The continuation on the energy ``y K y / 2 - b y`` from zero, Newton from the start."""

    def fn(y, args):
        r = stiffness @ y - load
        return r, (0.5 * y @ (stiffness @ y) - load @ y, jnp.ones_like(y))

    solver = PseudoTransientContinuation(
        rtol=0.0, atol=1e-12, symmetric=True, newton_start=True, ahead=ahead
    )
    y0 = jnp.zeros(load.shape[0], jnp.float64)
    return optx.root_find(fn, solver, y0, has_aux=True, max_steps=50, throw=False)


def test_a_solve_ends_where_the_step_tried_ahead_lands_within_the_tolerance():
    # A quadratic energy: the Newton step from the start lands on the solution. With ``ahead``
    # the step tried after the first linearisation finds the residual there within the
    # tolerance, and the solve ends with that one linearisation, at the solution; without it
    # the solve linearises there too (two steps).
    rng = np.random.default_rng(1)
    m = rng.normal(size=(5, 5))
    stiffness = jnp.asarray(m @ m.T + 5.0 * np.eye(5))
    load = jnp.asarray(rng.normal(size=5))
    for ahead, steps in ((True, 1), (False, 2)):
        sol = _quadratic_solve(stiffness, load, ahead)
        assert sol.result == optx.RESULTS.successful
        assert int(sol.stats["num_steps"]) == steps, (ahead, int(sol.stats["num_steps"]))
        np.testing.assert_allclose(sol.value, np.linalg.solve(stiffness, load), rtol=1e-12)
    # Too soft a stiffness for its stability to carry over the step: the solve takes the step
    # and linearises at the solution.
    soft = stiffness - (np.linalg.eigvalsh(stiffness)[0] - 1e-2) * jnp.eye(5)
    sol = _quadratic_solve(soft, load, True)
    assert sol.result == optx.RESULTS.successful
    assert int(sol.stats["num_steps"]) == 2, int(sol.stats["num_steps"])
    assert np.abs(np.asarray(soft @ sol.value - load)).max() <= 1e-12


def test_follower_force_residual_is_the_same_under_jit():
    # The follower force's site is known (the solver makes it a Python float first): under jit
    # its frames must come from the same knot path as outside it. Stacked into a tracer, the
    # site took the grid path (here 5e-6 apart), and every solver step of a follower scene
    # cost several times more.
    force = pj.PointForce((0.0, 0.5, 2.0), segment=1, s=0.7, follower=True)
    robot = pj.Robot([pj.Segment(0.1, 0.02, 1e3, 0.1), pj.Segment(0.1, 0.02, 1e3, 0.1)])
    scene = pj.Scene(robot, pj.PolynomialCurvature(order=2), loads=(force,))
    scene = static_load_sites(scene)
    q = jnp.asarray(np.random.default_rng(0).normal(0.0, 1.0, scene.n_dofs))
    # Closed over, the scene's site stays a Python float, as outside jit.
    eager = np.asarray(jax.jit(lambda x: scene.residual(x, None))(q))
    jitted = np.asarray(eqx.filter_jit(lambda sc, x: sc.residual(x, None))(scene, q))
    np.testing.assert_allclose(jitted, eager, rtol=1e-13, atol=1e-13 * np.abs(eager).max())


@pytest.mark.slow  # hard rows of a follower-loaded robot (~23 s): CI's slow step
def test_follower_rows_of_the_paper_robot_converge_in_few_steps():
    # Commands of the paper's robot (PAC) under the 3.41 N tip follower force that used to
    # crawl: with |r|^2 as the merit, the continuation's steps were cut by the line search for
    # tens of steps while the first segment's bending plane turned (96 and 62 steps). The third
    # row used to converge to a point whose symmetric stiffness is indefinite (smallest scaled
    # eigenvalue -0.0099, tip at (-0.6, -12.1, -379.8) mm), an attractor of the flow that each
    # escape led back to, which held the row to the 300-step limit; with the frozen-work merit
    # it stopped there, reported unstable (13, 11 and 15 steps). Since steps move the bending
    # vector (:meth:`pacjax._statics.problem.ScaledProblem.moved`) and dt may grow 100x a step, the
    # straight start reaches a stable equilibrium (eigenvalue 0.068, tip (18.8, -5.7, -378.9)
    # mm), and so does a start at that indefinite point, by its escape (10, 10, 15 and 22
    # steps).
    force = pj.PointForce((0.0, 0.0, 3.41), segment=2, s=1.0, follower=True)
    scene = pj.presets.stella2023(pj.PAC(), loads=(force,), quadrature_points=8)
    controls = jnp.asarray(
        [
            [0.00308, 0.00749, 0.01017, 0.01145, 0.00175, 0.00385, 0.01312, 0.00242, 0.00597],
            [0.00063, 0.0017, 0.00358, 0.0064, 0.01954, 0.0159, 0.00042, 0.01467, 0.00336],
            [0.00109, 0.00039, 2e-05, 0.01692, 0.01239, 0.00968, 0.00678, 0.01176, 0.01849],
            [0.00109, 0.00039, 2e-05, 0.01692, 0.01239, 0.00968, 0.00678, 0.01176, 0.01849],
        ]
    )
    indefinite = [0.024686, -0.05179, -1.25721, -0.000739, -0.111422, -0.089255, -1.198298]
    indefinite += [-0.012685, 0.290409, -0.060791, -0.96131, -0.01205]
    q0 = np.zeros((4, scene.n_dofs))
    q0[3] = indefinite
    eq = pj.solve_batch(scene, controls, q0, fallback=False, progress=False)
    steps = np.asarray(eq.steps)
    assert np.all(np.asarray(eq.converged)), np.asarray(eq.residual_norm)
    assert np.all(steps <= 30), steps
    assert np.all(np.asarray(eq.stable)), np.asarray(eq.min_hessian_eigenvalue)
    np.testing.assert_allclose(eq.q[3], eq.q[2], atol=1e-8)
    # Each is an equilibrium of the full residual, follower force included.
    residual = eqx.filter_jit(lambda sc, x, v: sc.residual(x, v))  # op by op: 400+ compiles
    for u, q in zip(controls, eq.q, strict=True):
        force_scale = float(jnp.max(jnp.abs(residual(scene, q, u))))
        assert force_scale < 1e-6, force_scale


def _energy_problem(energy):
    """A conservative problem for the root finder: the gradient of ``energy`` and its value as
    the merit."""

    def fn(y, args):
        return jax.grad(energy)(y), (energy(y), jnp.ones_like(y))

    return fn


def _steps(fn, y0, newton_start):
    solver = PseudoTransientContinuation(
        rtol=0.0, atol=1e-12, symmetric=True, newton_start=newton_start
    )
    sol = optx.root_find(fn, solver, y0, has_aux=True, max_steps=200, throw=False)
    assert float(jnp.max(jnp.abs(fn(sol.value, None)[0]))) <= 1e-12
    return int(sol.stats["num_steps"]), np.asarray(sol.value)


def test_newton_start_takes_newtons_steps_where_they_descend_and_hands_over_where_not():
    # Easy: Newton converges from the start; the continuation's first steps fall short of it.
    easy = _energy_problem(lambda y: jnp.sum(jnp.cosh(y - 0.7) + 0.1 * y**4))
    y0 = jnp.zeros(3)
    newton, y_newton = _steps(easy, y0, True)
    continuation, y_cont = _steps(easy, y0, False)
    np.testing.assert_allclose(y_newton, y_cont, atol=1e-12)
    assert newton < continuation, (newton, continuation)
    # Hard: Newton diverges from the start (each step cubes the distance), so the first full
    # step raises the energy and the continuation takes over; it still converges.
    hard = _energy_problem(lambda y: jnp.sum(jnp.sqrt(1.0 + (y - 3.0) ** 2)))
    _, y_hard = _steps(hard, y0, True)
    np.testing.assert_allclose(y_hard, 3.0, atol=1e-10)


@pytest.mark.slow  # 25 compilations (17 s): CI's slow step
def test_tentacle_in_strain_coordinates_converges_in_newtons_steps():
    scene = pj.presets.tentacle(pj.PolynomialCurvature(1))
    tensions = np.random.default_rng(1).uniform(0.0, 8.0, (8, 2))
    eq = pj.solve_batch(scene, tensions)
    assert np.all(np.asarray(eq.converged)) and np.all(np.asarray(eq.stable))
    # Plain Newton from straight took 4 iterations on such rows (the first step of the count
    # is the linearisation at the start); the continuation from dt = 1 took 7 steps.
    assert int(np.max(eq.steps)) <= 6, np.asarray(eq.steps)


@pytest.mark.slow  # 7 compilations (26 s): CI's slow step
def test_pac_tentacle_takes_newtons_steps_from_a_long_first_step():
    # PCC/PAC start the continuation at dt = 1e3 (pacjax._statics.options.POLAR_INITIAL_DT):
    # long enough for near-Newton steps along the bending, short enough to hold the plane
    # angles, whose stiffness at the aligned start is the regulariser's. From dt = 1 the hanging
    # tentacle crept up its soft modes for two more steps.
    scene = pj.presets.tentacle(pj.PAC())
    tensions = np.random.default_rng(1).uniform(0.0, 8.0, (8, 2))
    eq = pj.solve_batch(scene, tensions)
    short = pj.solve_batch(scene, tensions, options=pj.SolverOptions(initial_dt=1.0))
    for result in (eq, short):
        assert np.all(np.asarray(result.converged)) and np.all(np.asarray(result.stable))
    np.testing.assert_allclose(np.asarray(eq.q), np.asarray(short.q), atol=1e-8)
    # (the batch's rows end where the step tried ahead lands: one step fewer than single solves)
    assert int(np.max(eq.steps)) <= 5, np.asarray(eq.steps)
    assert int(np.min(short.steps)) >= 6, np.asarray(short.steps)


def test_a_segment_straight_to_round_off_keeps_newtons_steps():
    # A tail segment that nothing bends (no tendon in it, gravity of 1e-20 m/s^2, as a
    # property-based draw had) ends with curvatures of ~1e-22: straight to round-off. Its plane
    # angle, held by the regulariser alone, must take the Newton step; carried along with a
    # bending vector of that size, the angle turned by a random fraction of the step and the
    # solve crept for 76-105 steps (batch and single then disagreed on success at the limit).
    segments = [pj.Segment(0.1, 0.01, 1000.0, linear_density=0.1) for _ in range(3)]
    tendons = [
        pj.Tendon(0, 3.0, 0.01, mode="tension", routing="channel"),
        pj.Tendon(1, -2.8, 0.01, mode="tension", routing="channel"),
    ]
    loads = [pj.Gravity(1e-20), pj.PointMass(0.05, 2, 0.5)]
    scene = pj.Scene(pj.Robot(segments), pj.PAC(), tendons=tendons, loads=loads)
    eq = pj.solve_batch(scene, np.array([[2.0, 1.0], [3.0, 0.2]]), fallback=False, progress=False)
    assert np.all(np.asarray(eq.successful)), eq.reason
    tail = np.asarray(eq.q).reshape(2, 3, -1)[:, 2, :2]
    assert np.all(np.abs(tail) < 1e-15), tail
    assert int(np.max(eq.steps)) <= 10, np.asarray(eq.steps)


def test_an_s_shaped_pac_segment_steps_in_its_polar_coordinates():
    # A horizontal PAC cantilever under gravity and a 2 N tip force bends into an S (c0 ~ 8,
    # c1 ~ -11: its end turned by less than half of what it bends). The plane's moves
    # (ScaledProblem.moved) are singular there and the Newton model is the polar Hessian: with
    # the step on the bending vector regardless, these rows took 28, 29, 13 and 21 steps.
    inertia, area = np.pi * 0.01**4 / 4, np.pi * 0.01**2
    segment = pj.Segment(0.3, 5.05e5 * inertia, 5.05e5 * area / 0.3, linear_density=1500 * area)
    robot = pj.Robot([segment], base_rotation=pj.presets.MOUNTS["horizontal"])
    scene = pj.Scene(robot, pj.PAC(), (), (pj.Gravity(), pj.PointForce(np.zeros(3), 0, 1.0)))
    forces = jnp.asarray(
        [[-1.8125, 1.3377, 0.1497], [-1.7182, -0.5525, 0.1005], [-1.78, 0.0866, -0.9805]]
        + [[-1.8036, 0.9036, 0.8606]]
    )
    eq = pj.solve_batch(
        scene,
        jnp.zeros((4, 0)),
        params=forces,
        update=lambda sc, f: eqx.tree_at(lambda s: s.loads[1].force, sc, f),
        fallback=False,
        progress=False,
    )
    assert np.all(np.asarray(eq.successful)), eq.reason
    assert int(np.max(eq.steps)) <= 15, np.asarray(eq.steps)
