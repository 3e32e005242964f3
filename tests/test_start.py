"""The solver's start: a straight PCC/PAC segment gets the bending plane of the force on it."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from marks import slow

import pacjax as pj
from pacjax._statics.problem import ScaledProblem
from pacjax.cli.bench import random_commands

ANGLES = np.asarray(pj.presets.TENDON_ANGLES)


def _aligned(scene, controls, q0=None, tol=1e-10):
    """The start the solver takes from ``q0`` (default straight), per segment."""
    q0 = scene.zeros() if q0 is None else jnp.asarray(q0, float)
    q = _aligned_q(scene, jnp.asarray(controls, float), q0, float(tol))
    return np.asarray(q).reshape(scene.n_segments, scene.dofs_per_segment)


@eqx.filter_jit  # compiled once per scene structure (op by op it took seconds a call)
def _aligned_q(scene, controls, q0, tol):
    problem = ScaledProblem.build(scene, controls)
    return problem.q(problem.aligned(q0 / problem.sigma, tol))


# Compiled once per scene structure (op by op: ~100 small compilations a scene). The step
# (``moved``) stays op by op: compiled, its division by sigma and the test's product with sigma
# can round differently from the product of the parts that the tests compare exactly.
_build = eqx.filter_jit(ScaledProblem.build)
# The markers of a batch of configurations, one program (a loop over rows ran op by op).
_batch_markers = eqx.filter_jit(jax.vmap(pj.markers, in_axes=(None, 0)))


def _pull(segment, tendon, amount=0.01):
    controls = np.zeros(9)
    controls[3 * segment + tendon] = amount
    return controls


@pytest.mark.parametrize("model", [slow(pj.PCC()), pj.PAC()], ids=["PCC", "PAC"])
@pytest.mark.parametrize("tendon", [0, 1, 2])
def test_straight_segment_turns_to_its_pulled_tendon(model, tendon):
    scene = pj.presets.stella2023(model, tip_mass=0.2)
    start = _aligned(scene, _pull(1, tendon))
    phi = start[:, -2]
    # The plane through the tendon, in the half (-pi/2, pi/2] that the regulariser prefers.
    assert np.cos(2 * (phi[1] - ANGLES[tendon])) == pytest.approx(1.0, abs=1e-12)
    assert -0.5 * np.pi < phi[1] <= 0.5 * np.pi
    # Segments 0 and 2 feel no bending force at the straight state (Bowden tendon, hanging
    # payload on the axis): the first keeps its phi, the last takes segment 1's plane. The
    # start stays straight.
    assert phi[0] == 0.0 and phi[2] == phi[1]
    assert np.all(start[:, :-2] == 0.0) and np.all(start[:, -1] == 0.0)

    # The solve from there bends the segment towards the tendon (c0 picks the side).
    eq = pj.solve_equilibrium(scene, _pull(1, tendon))
    assert bool(eq.converged) and bool(eq.stable)
    q = np.asarray(eq.q).reshape(3, -1)
    bend = q[1, 0] * np.array([np.cos(q[1, -2]), np.sin(q[1, -2])])
    direction = np.array([np.cos(ANGLES[tendon]), np.sin(ANGLES[tendon])])
    assert bend @ direction > 0.9 * np.linalg.norm(bend)


def test_bent_segments_and_small_forces_keep_their_angle():
    scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
    q0 = np.zeros((3, 4))
    q0[0] = [0.5, 0.0, 0.3, 0.0]  # bent: its phi is defined and must stay
    start = _aligned(scene, _pull(0, 0) + _pull(2, 1), q0.reshape(-1))
    assert start[0, 2] == 0.3
    # Segment 2 turns to its tendon, tilted slightly by the weight now that segment 0 is bent.
    assert np.cos(2 * (start[2, 2] - ANGLES[1])) == pytest.approx(1.0, abs=1e-3)
    # Segment 1 sags under its weight in the plane in which segment 0 tilts it.
    assert np.cos(2 * (start[1, 2] - 0.3)) == pytest.approx(1.0, abs=1e-12)
    # No pull: nothing bends the straight robot (gravity acts along its axis).
    assert np.all(_aligned(scene, np.zeros(9)) == 0.0)
    # A force below the tolerance turns nothing.
    assert np.all(_aligned(scene, _pull(2, 1), tol=1e3)[:, 2] == 0.0)


def test_unloaded_straight_segments_take_the_plane_before_them():
    """One tendon of section 1 pulled: sections 2 and 3 carry no bending force at the straight
    start, and are loaded only through section 1's bend, in its plane. Left at phi = 0 they
    sat on a saddle in that plane, which the solver had to find and leave (10 steps against 6
    from the aligned start)."""
    scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
    controls = _pull(0, 0, 0.04)
    start = _aligned(scene, controls)
    assert np.all(start[:, 2] == start[0, 2])
    aligned = pj.solve_equilibrium(scene, controls, fallback=False)
    q0 = np.zeros((3, 4))
    q0[:, 0] = 1e-9  # not straight: the start keeps phi = 0 (the solver's start before)
    plain = pj.solve_equilibrium(scene, controls, q0.reshape(-1), fallback=False)
    for eq in (aligned, plain):
        assert bool(eq.converged) and bool(eq.stable)
    tips = [np.asarray(pj.markers(scene, eq.q))[-1] for eq in (aligned, plain)]
    np.testing.assert_allclose(tips[0], tips[1], atol=1e-5)
    assert int(aligned.steps) <= 0.6 * int(plain.steps), (int(aligned.steps), int(plain.steps))


@pytest.mark.parametrize(
    "model",
    [pj.PAC(frame="paper"), pj.PolynomialCurvature(1)],
    ids=["PAC-paper-frame", "Poly1"],
)
def test_models_without_a_free_plane_angle_start_where_asked(model):
    # In the paper's frame phi also twists the frame; Cartesian models have no angle.
    scene = pj.presets.stella2023(model, tip_mass=0.2)
    assert model.free_plane_angle() is None
    assert np.all(_aligned(scene, _pull(1, 2)) == 0.0)


@pytest.mark.slow  # 24 commands solved twice, each way compiled: 16 s for PCC
@pytest.mark.parametrize("model", [pj.PCC(), pj.PAC()], ids=["PCC", "PAC"])
def test_aligned_start_reaches_the_same_equilibria_in_fewer_steps(model):
    scene = pj.presets.stella2023(model, tip_mass=0.2)
    commands = random_commands(24, seed=3)
    aligned = pj.solve_batch(scene, commands, fallback=False)
    # A start bent by 1e-9 rad/m is not straight, so it keeps phi = 0: the solver's start
    # before the alignment, to within that bend.
    q0 = np.zeros((3, scene.dofs_per_segment))
    q0[:, 0] = 1e-9
    plain = pj.solve_batch(scene, commands, np.tile(q0.reshape(-1), (24, 1)), fallback=False)
    for eq in (aligned, plain):
        assert np.all(eq.converged) and np.all(eq.stable)
    tips = [np.asarray(_batch_markers(scene, eq.q))[:, -1] for eq in (aligned, plain)]
    # Both are minima of the same energy; they may differ by the regulariser on phi
    # (relative 1e-6), which prefers one of the two equivalent (c0, phi) of a bent segment.
    np.testing.assert_allclose(tips[0], tips[1], atol=1e-5)
    assert np.mean(aligned.steps) < 0.8 * np.mean(plain.steps)


def test_simulation_start_turns_straight_segments_at_rest_only():
    import jax

    from pacjax._dynamics.simulate import aligned_rest_start

    scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
    u = jnp.asarray(_pull(0, 0) + _pull(2, 1))
    zero = jnp.zeros(scene.n_dofs)
    start = np.asarray(aligned_rest_start(scene, u, zero, zero, jnp.asarray(0.0)))
    start = start.reshape(3, 4)
    assert np.cos(2 * (start[0, 2] - ANGLES[0])) == pytest.approx(1.0, abs=1e-12)
    assert np.cos(2 * (start[2, 2] - ANGLES[1])) == pytest.approx(1.0, abs=1e-12)
    assert start[1, 2] == start[0, 2]  # no force on it: the plane of the segment before
    # A straight segment already bending (c0 rate) keeps the plane of its velocity.
    qdot = zero.at[8].set(0.3)
    moving = np.asarray(aligned_rest_start(scene, u, zero, qdot, jnp.asarray(0.0)))
    assert moving.reshape(3, 4)[2, 2] == 0.0
    # Controls given as a function of time are read at t0.
    at_t0 = aligned_rest_start(scene, lambda t: u * (1.0 + t), zero, zero, jnp.asarray(0.0))
    np.testing.assert_array_equal(np.asarray(at_t0), start.reshape(-1))
    # Only the coordinates of the same configuration change: d(start)/d(q0) is the identity.
    jac = jax.jacfwd(lambda q: aligned_rest_start(scene, u, q, zero, jnp.asarray(0.0)))(zero)
    np.testing.assert_array_equal(np.asarray(jac), np.eye(scene.n_dofs))


@pytest.mark.parametrize("model", [pj.PCC(), pj.PAC()], ids=["PCC", "PAC"])
def test_a_step_moves_the_bending_vector_along_a_line(model):
    # A continuation step moves a segment's bending vector B = theta e(phi) (theta = beta . c,
    # the bending angle at its end) by its linear change, dtheta e(phi) + theta dphi e'(phi),
    # instead of moving phi along the arc; the curvatures turn with the plane, by less than a
    # quarter turn (a bend through straight goes on with theta < 0); a segment whose end is
    # not turned, and dL, move as y + dy; the move is y + dy to first order.
    scene = pj.presets.stella2023(model, tip_mass=0.2)
    problem = _build(scene, jnp.asarray(_pull(1, 0), float))
    n, d, k = scene.n_segments, scene.dofs_per_segment, model.free_plane_angle()
    beta = np.asarray(model.plane_angle_basis(jnp.ones(())))
    rng = np.random.default_rng(4)
    y = 0.4 * rng.normal(size=(n, d))
    y[0, :k] = 0.0  # a straight segment
    dy = 0.3 * rng.normal(size=(n, d))
    dy[1, :k] = -2.0 * y[1, :k]  # this bend passes through straight
    q, dq = (np.asarray(problem.q(jnp.asarray(v.reshape(-1)))).reshape(n, d) for v in (y, dy))
    moved = problem.moved(jnp.asarray(y.reshape(-1)), jnp.asarray(dy.reshape(-1)))
    q_new = np.asarray(problem.q(moved)).reshape(n, d)

    def bending(q):
        phi = q[:, k]
        return (q[:, :k] @ beta)[:, None] * np.stack([np.cos(phi), np.sin(phi)], axis=1), phi

    b, phi = bending(q)
    b_new, phi_new = bending(q_new)
    e = np.stack([np.cos(phi), np.sin(phi)], axis=1)
    e_turned = np.stack([-np.sin(phi), np.cos(phi)], axis=1)
    theta, dtheta = q[:, :k] @ beta, dq[:, :k] @ beta
    line = b + dtheta[:, None] * e + (theta * dq[:, k])[:, None] * e_turned
    np.testing.assert_allclose(b_new[1:], line[1:], rtol=0, atol=1e-14)
    # The curvatures turn with the plane: c' e(phi') is the projection of c e(phi) + dc e(phi)
    # + c dphi e'(phi) on the new plane.
    turn = phi_new - phi
    along = (q + dq)[:, :k] * np.cos(turn)[:, None]
    np.testing.assert_allclose(
        q_new[1:, :k], (along + q[:, :k] * (dq[:, k] * np.sin(turn))[:, None])[1:], atol=1e-15
    )
    assert np.all(np.abs(turn) <= 0.5 * np.pi)
    assert (q_new[1, :k] @ beta) * theta[1] < 0
    np.testing.assert_array_equal(q_new[0], q[0] + dq[0])
    np.testing.assert_allclose(q_new[:, k + 1 :], q[:, k + 1 :] + dq[:, k + 1 :], rtol=1e-15)

    def gap(t):
        step = t * dy.reshape(-1)
        moved = problem.moved(jnp.asarray(y.reshape(-1)), jnp.asarray(step))
        return np.max(np.abs(np.asarray(moved) - y.reshape(-1) - step))

    assert 50 < gap(1e-3) / gap(1e-4) < 200
    still = problem.moved(jnp.zeros(n * d), jnp.zeros(n * d))
    assert np.all(np.asarray(still) == 0.0)


@eqx.filter_jit
def _newton_models(problem, y):
    """The solver's Jacobian at ``y``, the Hessian of the energy along the moves from ``y``
    (scaled like it), and the polar Jacobian (the residual's derivative in ``y``)."""
    jac, _ = problem.linearise(y)
    along = jax.hessian(lambda dy: problem.energy(problem.moved(y, dy)))(jnp.zeros_like(y))
    return jac, (problem.row / problem.sigma)[:, None] * along, jax.jacfwd(problem.residual)(y)


@pytest.mark.slow  # one large program (the energy's Hessian along the moves), 25 s
@pytest.mark.parametrize("model", [pj.PCC(), pj.PAC()], ids=["PCC", "PAC"])
def test_the_newton_model_is_the_energy_along_the_moves(model):
    # A conservative PCC/PAC scene's Jacobian is the Hessian of E(moved(y, dy)) at dy = 0, not
    # the polar one, except on a segment whose end angle is mostly cancelled (an S of PAC),
    # where the moves are singular and the polar Jacobian is kept; at an equilibrium the two
    # agree (the difference vanishes with the gradient).
    scene = pj.presets.stella2023(model, tip_mass=0.2)
    commands = jnp.asarray(_pull(1, 0, 0.02) + _pull(2, 1, 0.01), float)
    problem = _build(scene, commands)
    n, d, k = scene.n_segments, scene.dofs_per_segment, model.free_plane_angle()
    rng = np.random.default_rng(7)
    y = np.zeros((n, d))
    y[:, :k] = 0.2 + 0.3 * rng.random((n, k))  # bent, every curvature the same sign
    y[:, k] = rng.uniform(-1.0, 1.0, n)
    y[:, -1] = 0.01 * rng.normal(size=n)
    if k == 2:
        y[2, :k] = [0.5, -0.8]  # an S: theta = 0.1 against 0.9 of spread
    jac, along, polar = (np.asarray(m) for m in _newton_models(problem, jnp.asarray(y.ravel())))
    scale = np.max(np.abs(jac))
    bent = slice(0, 2 * d) if k == 2 else slice(0, n * d)
    np.testing.assert_allclose(jac[bent, bent], along[bent, bent], rtol=0, atol=1e-12 * scale)
    assert np.max(np.abs(jac - polar)) > 1e-3 * scale
    if k == 2:
        s_block = slice(2 * d, 3 * d)
        np.testing.assert_allclose(
            jac[s_block, s_block], polar[s_block, s_block], atol=1e-12 * scale
        )

    eq = pj.solve_equilibrium(scene, commands)
    assert bool(eq.converged)
    jac, _, polar = _newton_models(problem, eq.q / problem.sigma)
    np.testing.assert_allclose(np.asarray(jac), np.asarray(polar), rtol=0, atol=1e-8 * scale)


def test_other_models_step_to_y_plus_dy():
    for model in (pj.PAC(frame="paper"), pj.PolynomialCurvature(1)):
        scene = pj.presets.stella2023(model, tip_mass=0.2)
        problem = _build(scene, jnp.asarray(_pull(1, 0), float))
        y, dy = np.random.default_rng(1).normal(size=(2, scene.n_dofs))
        np.testing.assert_array_equal(problem.moved(jnp.asarray(y), jnp.asarray(dy)), y + dy)


@pytest.mark.slow
def test_the_bending_vector_step_reaches_the_same_equilibria_in_fewer_steps(monkeypatch):
    scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
    commands = random_commands(32, seed=5)
    curved = pj.solve_batch(scene, commands, fallback=False)
    monkeypatch.setattr(ScaledProblem, "moved", lambda self, y, dy: y + dy)
    jax.clear_caches()  # the compiled solver has the method traced in
    straight = pj.solve_batch(scene, commands, fallback=False)
    monkeypatch.undo()
    jax.clear_caches()
    for eq in (curved, straight):
        assert np.all(eq.converged) and np.all(eq.stable)
    tips = [np.asarray(_batch_markers(scene, eq.q))[:, -1] for eq in (curved, straight)]
    np.testing.assert_allclose(tips[0], tips[1], atol=1e-6)
    assert np.mean(curved.steps) < 0.9 * np.mean(straight.steps), (
        np.mean(curved.steps),
        np.mean(straight.steps),
    )


def test_round_off_curvature_counts_as_straight():
    """An equilibrium solved from the straight state comes back with curvatures of about 1e-18:
    still straight, so the start (of a solve or a simulation from it) turns its planes."""
    scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
    q0 = np.zeros((3, 4))
    q0[:, :2] = [[-1.9e-18, -8e-19], [-1.2e-18, -1.9e-18], [-2.9e-19, 2.2e-18]]
    start = _aligned(scene, _pull(1, 0), q0.reshape(-1))
    assert np.cos(2 * (start[1, 2] - ANGLES[0])) == pytest.approx(1.0, abs=1e-12)
    assert start[2, 2] == start[1, 2]
