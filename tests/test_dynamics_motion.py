"""Dynamics over time (CI's slow step): a damped step response settles on the statics, the
undamped energy is conserved over 100 periods, and a simulated free vibration has the
Euler-Bernoulli frequency. Split from ``test_dynamics.py`` so that a parallel run can give these
minutes to another worker."""

import math

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from dynamics_scenes import CONTROLS, SCENE, cantilever, free_scene

import pacjax as pj
from pacjax import dynamics as dyn
from pacjax._model.inertia import kinetic_energy, mass_matrix


@pytest.mark.long(minutes=0.7)
@pytest.mark.slow
def test_damped_motion_settles_on_equilibrium():
    """A step to the tendon commands, modally damped at 0.7, settles on the statics' solution.
    The tendons are springs of at most 55 Hz here, not stiff: an explicit solver takes 10,836
    steps for the 4 s in 37 s on 2 cores (Kvaerno5: 1,104 steps, 99 s, 90 of them compiling),
    and both end within 1e-13 of the equilibrium."""
    eq = pj.solve_equilibrium(SCENE, CONTROLS, tol=1e-12)
    assert bool(eq.converged)
    traj = pj.simulate(
        SCENE,
        (0.0, 4.0),
        CONTROLS,
        saveat=[0.0, 2.0, 4.0],
        damping=pj.Damping.modal(SCENE, 0.7),
        solver=diffrax.Tsit5(),
        rtol=1e-9,
        atol=1e-11,
    )
    assert bool(traj.successful)
    assert float(jnp.max(jnp.abs(traj.q[0]))) == 0.0
    assert float(jnp.max(jnp.abs(traj.q[-1] - eq.q))) < 1e-6
    assert float(jnp.max(jnp.abs(traj.qdot[-1]))) < 1e-5


@pytest.mark.long(minutes=1.0)
@pytest.mark.slow
def test_energy_is_conserved_over_100_periods():
    """Undamped, without tendons: the total energy stays within 1e-6 of its start over 100
    periods of the lowest mode. Dopri8 at rtol 1e-9 keeps it within 1.7e-8 (18,195 steps, 51 s
    on 2 cores with compilation; at rtol 1e-10, 1.7e-9 in 23,954 steps and 67 s; at 1e-12, 5e-11
    in 40,509 steps)."""
    scene = free_scene()
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
        rtol=1e-9,
        atol=1e-11,
    )
    assert bool(traj.successful)
    energy = jax.vmap(lambda q, v: dyn.total_energy(scene, q, v))(traj.q, traj.qdot)
    kinetic = jax.vmap(lambda q, v: kinetic_energy(scene, q, v))(traj.q, traj.qdot)
    assert float(jnp.max(kinetic)) > 0.1 * abs(float(energy[0]))  # it does move
    assert float(jnp.max(jnp.abs(energy - energy[0]))) < 1e-6 * abs(float(energy[0]))


@pytest.mark.slow
def test_cantilever_free_vibration_frequency():
    """Simulated free vibration of the high-order cantilever: zero crossings give the
    Euler-Bernoulli frequency. The body starts bent in its first mode shape (the lowest
    eigenvector of ``K v = w^2 M v`` at rest), so that three periods show the frequency. Undamped
    and without tendons the motion is not stiff, so an explicit solver does it; released from two
    coordinates instead, the modes up to 845 Hz it excited took 48k Dopri8 steps at rtol 1e-9
    for five periods (318 s on 2 cores) against 2.4k here (30 s)."""
    scene, ei, density, length = cantilever(pj.PolynomialCurvature(order=3), 2)
    expected = 1.8751**2 * math.sqrt(ei / (density * length**4)) / (2 * math.pi)
    rest = scene.zeros()
    stiffness = jax.jit(jax.hessian(scene.elastic_energy))(rest)
    mass = jax.jit(lambda q: mass_matrix(scene, q))(rest)
    _, modes = scipy.linalg.eigh(np.asarray(stiffness), np.asarray(mass))
    mode_q0 = jnp.asarray(1e-3 * modes[:, 0] / np.abs(modes[:, 0]).max())
    t1 = 3.0 / expected
    ts = np.linspace(0.0, t1, 2001)
    traj = pj.simulate(
        scene,
        (0.0, t1),
        q0=mode_q0,
        saveat=ts,
        damping=pj.Damping(),
        solver=diffrax.Dopri8(),
        rtol=1e-7,
        atol=1e-10,
    )
    assert bool(traj.successful)
    tip = np.stack([np.asarray(pj.tip_pose(scene, q)[0]) for q in traj.q[::4]])
    swing = tip - tip.mean(axis=0)
    x = swing @ (swing[0] / np.linalg.norm(swing[0]))  # along the mode's plane
    crossings = ts[::4][:-1][np.sign(x[:-1]) != np.sign(x[1:])]
    freq = 0.5 / np.mean(np.diff(crossings))
    assert abs(freq / expected - 1) < 0.02
