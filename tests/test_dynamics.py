"""Dynamics: inertia by autodiff, consistency with statics, modal frequencies, simulation.

One small scene structure (one segment, linear polynomial curvature, 4 Gauss points, gravity,
an end mass and two length-mode tendons) is shared by the default tests, so that the simulator
compiles once for them. The checks:

- ``M`` is the Hessian of the kinetic energy in ``qdot``; the forward-mode Coriolis forces equal
  the Lagrangian reference and the Christoffel form of ``dM/dq``;
- at rest velocity the dynamic forces are minus the static residual (motor law = statics);
- the first bending frequency of a uniform cantilever matches Euler-Bernoulli within 2 %;
- a damped step response settles on ``solve_equilibrium``'s state within 1e-6;
- (slow) the undamped, unactuated energy drifts by less than 1e-6 over 100 periods, the
  gradient of a trajectory with respect to the damping matches finite differences (on this
  scene, and on a smaller one that finishes on 2 cores), and a simulated free vibration has
  the modal frequency.
"""

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pacjax as pj
from pacjax import dynamics as dyn
from pacjax._dynamics import simulate as simulate_module
from pacjax._model.inertia import body_dynamics, coriolis_forces, kinetic_energy, mass_matrix

HANGING = np.diag([1.0, -1.0, -1.0])


def _scene(density=0.3):
    segment = pj.Segment(0.15, 0.02, 600.0, linear_density=density, radius=0.012)
    guides = (0.0, 0.5, 1.0)
    tendons = (
        pj.Tendon(0, 0.0, 0.01, gain=2.0e3, guides=guides),
        pj.Tendon(0, 2.1, 0.01, gain=2.0e3, guides=guides),
    )
    loads = (pj.Gravity(), pj.PointMass(0.03, 0, 1.0))
    return pj.Scene(
        pj.Robot([segment], base_rotation=HANGING),
        pj.PolynomialCurvature(order=1),
        tendons=tendons,
        loads=loads,
        quadrature_points=4,
    )


SCENE = _scene()
CONTROLS = jnp.array([0.008, 0.002])
RNG = np.random.default_rng(0)
Q = jnp.asarray(RNG.normal(size=SCENE.n_dofs) * 0.3).at[-1].set(-0.004)
QDOT = jnp.asarray(RNG.normal(size=SCENE.n_dofs))


@eqx.filter_jit
def _inertia_terms(scene, q, qdot):
    mass, bias = body_dynamics(scene, q, qdot)
    hessian = jax.hessian(lambda v: kinetic_energy(scene, q, v))(qdot)
    d_mass = jax.jacfwd(lambda x: mass_matrix(scene, x))(q)  # [i, j, k] = dM_ij / dq_k
    return mass, bias, hessian, d_mass, coriolis_forces(scene, q, qdot)


@pytest.mark.slow  # compiles second and third derivatives of the kinematics
def test_inertia_by_autodiff():
    mass, bias, hessian, d_mass, lagrangian = _inertia_terms(SCENE, Q, QDOT)
    scale = float(jnp.max(jnp.abs(mass)))
    assert jnp.max(jnp.abs(mass - hessian)) < 1e-12 * scale
    assert jnp.min(jnp.linalg.eigvalsh(mass)) > 0
    christoffel = jnp.einsum("ijk,j,k->i", d_mass, QDOT, QDOT) - 0.5 * jnp.einsum(
        "jki,j,k->i", d_mass, QDOT, QDOT
    )
    size = float(jnp.max(jnp.abs(christoffel)))
    assert size > 0
    assert jnp.max(jnp.abs(bias - christoffel)) < 1e-9 * size
    assert jnp.max(jnp.abs(bias - lagrangian)) < 1e-9 * size


@pytest.mark.slow  # compiles second and third derivatives of the kinematics
def test_rest_velocity_recovers_statics():
    """M qddot = -F(q) at qdot = 0: the motor PD law reduces to the statics' tendon tension."""
    zero = jnp.zeros(SCENE.n_dofs)
    qddot = jax.jit(lambda q: dyn.accelerations(SCENE, q, zero, CONTROLS))(Q)
    mass = jax.jit(lambda q: mass_matrix(SCENE, q))(Q)
    residual = SCENE.residual(Q, CONTROLS)
    assert jnp.max(jnp.abs(mass @ qddot + residual)) < 1e-9 * jnp.max(jnp.abs(residual))


def test_slack_tendon_cannot_push():
    """A tendon longer than its commanded length does nothing, whatever the velocity."""
    q = jnp.zeros(SCENE.n_dofs)
    qdot = jnp.zeros(SCENE.n_dofs).at[0].set(5.0)  # bending fast: one tendon shortens
    controls = jnp.array([-0.01, -0.01])  # commands longer than the rest lengths: both slack
    model = simulate_module._Model.build(SCENE, pj.Damping(stiffness=0.05), 1e-6, q.dtype)
    force = model.tendon_forces(q, qdot, controls, jnp.zeros(2))
    assert jnp.all(force == 0.0)
    # taut and stretching: the derivative gain adds to the pull
    taut = model.tendon_forces(q, qdot, jnp.array([0.001, 0.001]), jnp.zeros(2))
    still = model.tendon_forces(q, jnp.zeros_like(qdot), jnp.array([0.001, 0.001]), jnp.zeros(2))
    assert jnp.max(jnp.abs(taut - still)) > 0


@pytest.mark.parametrize("frame", ["torsion_free", "paper"])
def test_material_damping_is_kelvin_voigt(frame):
    """``D(q) = beta J(q)^T K_s J(q)``: ``beta K_0`` at rest, and a bent PCC segment's
    bending-plane angle is damped by the curvature it rotates (it was undamped with the
    constant ``K_0``: a slow swing across the bending plane that lasted seconds)."""
    segment = pj.Segment(0.12, 0.02, 800.0, linear_density=0.3)
    scene = pj.Scene(pj.Robot([segment]), pj.PCC(frame=frame))
    model = simulate_module._Model.build(scene, pj.Damping(stiffness=1.0), 1e-6, jnp.float64)
    zero = jnp.zeros(scene.n_dofs)

    def damping_matrix(q):
        return jax.jacfwd(lambda v: model.material_damping(q, v))(zero)

    k0 = jax.hessian(scene.elastic_energy)(zero)
    np.testing.assert_allclose(damping_matrix(zero), k0, rtol=0, atol=1e-12 * float(k0.max()))
    c0 = 0.7  # q = [c0, phi, dL]
    d = damping_matrix(jnp.array([c0, 0.4, 0.0]))
    if frame == "torsion_free":
        # the rate of phi rotates the curvature vector: |du/dt| = c0 dphi/dt
        assert float(d[1, 1]) == pytest.approx(float(k0[0, 0] * c0**2 + k0[1, 1]), rel=1e-12)
    else:
        # the paper's frame twists with phi: phi is a torsion, damped as at rest
        assert float(d[1, 1]) == pytest.approx(float(k0[1, 1]), rel=1e-12)
    np.testing.assert_allclose(d, d.T, atol=1e-15)
    assert float(jnp.linalg.eigvalsh(d)[0]) > 0


def _cantilever(model, n_segments, ei=0.05, density=0.4, length=0.3):
    segments = [pj.Segment(length / n_segments, ei, 1e5, linear_density=density)] * n_segments
    return pj.Scene(pj.Robot(segments), model), ei, density, length


def test_cantilever_first_frequency_matches_euler_bernoulli():
    scene, ei, density, length = _cantilever(pj.PolynomialCurvature(order=3), 2)
    expected = 1.8751**2 * math.sqrt(ei / (density * length**4)) / (2 * math.pi)
    freqs = np.asarray(dyn.natural_frequencies(scene))
    # two bending planes: the lowest pair is the first bending mode
    assert abs(freqs[0] / expected - 1) < 0.02
    assert abs(freqs[1] / expected - 1) < 0.02
    assert freqs[2] > 5 * expected  # the next mode is the second bending mode


@pytest.mark.slow  # 330 s on 2 cores beside another job
def test_damped_motion_settles_on_equilibrium():
    eq = pj.solve_equilibrium(SCENE, CONTROLS, tol=1e-12)
    assert bool(eq.converged)
    traj = pj.simulate(
        SCENE,
        (0.0, 4.0),
        CONTROLS,
        saveat=[0.0, 2.0, 4.0],
        damping=pj.Damping.modal(SCENE, 0.7),
        rtol=1e-9,
        atol=1e-11,
    )
    assert bool(traj.successful)
    assert float(jnp.max(jnp.abs(traj.q[0]))) == 0.0
    assert float(jnp.max(jnp.abs(traj.q[-1] - eq.q))) < 1e-6
    assert float(jnp.max(jnp.abs(traj.qdot[-1]))) < 1e-5


def test_input_validation():
    with pytest.raises(ValueError, match="linear_density"):
        pj.simulate(_scene(density=0.0), (0.0, 1.0))
    with pytest.raises(ValueError, match="t_span"):
        pj.simulate(SCENE, (1.0, 0.0))
    with pytest.raises(ValueError, match="saveat"):
        pj.simulate(SCENE, (0.0, 1.0), saveat=[0.5, 2.0])
    with pytest.raises(ValueError, match="controls"):
        pj.simulate(SCENE, (0.0, 1.0), jnp.zeros(3))
    with pytest.raises(ValueError, match=r"controls\(t\)"):
        pj.simulate(SCENE, (0.0, 1.0), lambda t: jnp.zeros(3))
    with pytest.raises(ValueError, match="qdot0"):
        pj.simulate(SCENE, (0.0, 1.0), qdot0=jnp.zeros(2))
    with pytest.raises(ValueError, match="Damping.stiffness"):
        pj.Damping(stiffness=-1.0)
    with pytest.raises(ValueError, match="Damping.tendon"):
        pj.simulate(SCENE, (0.0, 1.0), damping=pj.Damping(tendon=jnp.ones(3)))
    with pytest.raises(TypeError, match="damping"):
        pj.simulate(SCENE, (0.0, 1.0), damping=0.1)


# ------------------------------------------------------------------------------ slow
def _free_scene():
    """No tendons, no damping: a conservative pendulum-like body (gravity and elasticity)."""
    segment = pj.Segment(0.15, 0.02, 600.0, linear_density=0.3, radius=0.012)
    return pj.Scene(
        pj.Robot([segment]),
        pj.PolynomialCurvature(order=1),
        loads=(pj.Gravity(),),
        quadrature_points=4,
    )


@pytest.mark.slow  # under 4 min on 2 cores (2026-11-27)
def test_energy_is_conserved_over_100_periods():
    scene = _free_scene()
    period = 1.0 / float(dyn.natural_frequencies(scene)[0])
    q0 = jnp.zeros(scene.n_dofs).at[0].set(0.4).at[2].set(-0.2)
    qdot0 = jnp.zeros(scene.n_dofs).at[3].set(3.0)
    traj = pj.simulate(
        scene,
        (0.0, 100 * period),
        q0=q0,
        qdot0=qdot0,
        saveat=np.linspace(0.0, 100 * period, 201),
        damping=pj.Damping(),
        solver=diffrax.Dopri8(),
        rtol=1e-12,
        atol=1e-14,
    )
    assert bool(traj.successful)
    energy = jax.vmap(lambda q, v: dyn.total_energy(scene, q, v))(traj.q, traj.qdot)
    kinetic = jax.vmap(lambda q, v: kinetic_energy(scene, q, v))(traj.q, traj.qdot)
    assert float(jnp.max(kinetic)) > 0.1 * abs(float(energy[0]))  # it does move
    assert float(jnp.max(jnp.abs(energy - energy[0]))) < 1e-6 * abs(float(energy[0]))


@pytest.mark.slow
@pytest.mark.expensive  # not yet seen to finish on 2 cores
def test_energy_is_conserved_by_the_default_implicit_solver():
    """Kvaerno5 (the default) with tendons as undamped springs: 100 periods."""
    period = 1.0 / float(dyn.natural_frequencies(SCENE, controls=CONTROLS)[0])
    q0 = jnp.zeros(SCENE.n_dofs).at[0].set(0.3)
    t1 = 100 * period
    traj = pj.simulate(
        SCENE,
        (0.0, t1),
        CONTROLS,
        q0=q0,
        saveat=np.linspace(0.0, t1, 201),
        damping=pj.Damping(),
        rtol=1e-11,
        atol=1e-13,
        max_steps=400_000,
    )
    assert bool(traj.successful)
    energy = jax.vmap(lambda q, v: dyn.total_energy(SCENE, q, v, CONTROLS))(traj.q, traj.qdot)
    assert float(jnp.max(jnp.abs(energy - energy[0]))) < 1e-6 * abs(float(energy[0]))


def _damping_gradient(scene, controls, span, rtol, atol):
    """``d q_0(span) / d beta`` at ``beta = 0.02``, from a start bent by 0.2 rad: by reverse
    mode through the simulation (diffrax's checkpointed adjoint) and by central differences."""
    q0 = jnp.zeros(scene.n_dofs).at[0].set(0.2)

    def first_coordinate(beta):
        traj = pj.simulate(
            scene,
            (0.0, span),
            controls,
            q0=q0,
            saveat=[span],
            damping=pj.Damping(stiffness=beta),
            rtol=rtol,
            atol=atol,
        )
        return traj.q[-1, 0]

    beta = jnp.asarray(0.02)
    grad = jax.jit(jax.grad(first_coordinate))(beta)
    h = 1e-5
    fd = (first_coordinate(beta + h) - first_coordinate(beta - h)) / (2 * h)
    return float(grad), float(fd)


@pytest.mark.slow
@pytest.mark.expensive  # did not finish in 16 min on 2 cores beside another job
def test_gradient_with_respect_to_damping_matches_finite_differences():
    grad, fd = _damping_gradient(SCENE, CONTROLS, 0.3, rtol=1e-10, atol=1e-12)
    assert abs(grad) > 0
    assert abs(grad - fd) < 1e-4 * abs(fd)


@pytest.mark.slow
def test_gradient_of_a_small_trajectory_matches_finite_differences():
    """The same on the smallest scene with everything the damping enters: one
    constant-curvature segment released under gravity and an end mass, 0.1 s. The shared
    scene's version above has not finished on 2 cores; this one took 275 s there (nearly all
    compilation)."""
    segment = pj.Segment(0.15, 0.02, 600.0, linear_density=0.3, radius=0.012)
    scene = pj.Scene(
        pj.Robot([segment], base_rotation=HANGING),
        pj.PolynomialCurvature(order=0),
        loads=(pj.Gravity(), pj.PointMass(0.03, 0, 1.0)),
        quadrature_points=2,
    )
    grad, fd = _damping_gradient(scene, None, 0.1, rtol=1e-9, atol=1e-11)
    assert abs(fd) > 1.0  # the damping matters at this time
    assert abs(grad - fd) < 1e-6 * abs(fd)


@pytest.mark.slow  # 510 s on 2 cores beside CI (48k Dopri8 steps: modes up to 845 Hz)
def test_cantilever_free_vibration_frequency():
    """Simulated free vibration of the high-order cantilever: zero crossings give the
    Euler-Bernoulli frequency. Undamped and without tendons the motion is not stiff, so an
    explicit solver does it (the implicit default had not finished in 21 min on 2 cores)."""
    scene, ei, density, length = _cantilever(pj.PolynomialCurvature(order=3), 2)
    expected = 1.8751**2 * math.sqrt(ei / (density * length**4)) / (2 * math.pi)
    mode_q0 = jnp.zeros(scene.n_dofs).at[0].set(1e-3).at[9].set(1e-3)
    t1 = 5.0 / expected
    ts = np.linspace(0.0, t1, 2001)
    traj = pj.simulate(
        scene,
        (0.0, t1),
        q0=mode_q0,
        saveat=ts,
        damping=pj.Damping(),
        solver=diffrax.Dopri8(),
        rtol=1e-9,
        atol=1e-12,
    )
    assert bool(traj.successful)
    tip = np.stack([np.asarray(pj.tip_pose(scene, q)[0]) for q in traj.q[::4]])[:, 0]
    x = tip - tip.mean()
    crossings = ts[::4][:-1][np.sign(x[:-1]) != np.sign(x[1:])]
    freq = 0.5 / np.mean(np.diff(crossings))
    assert abs(freq / expected - 1) < 0.02
