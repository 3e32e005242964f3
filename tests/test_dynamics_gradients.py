"""Gradients through a simulated trajectory (CI's slow step): reverse mode through diffrax's
checkpointed adjoint against central differences. Split from ``test_dynamics.py`` so that a
parallel run can give its minutes of compilation to another worker."""

import diffrax
import jax
import jax.numpy as jnp
import pytest
from dynamics_scenes import small_scene

import pacjax as pj


def _damping_gradient(scene, controls, q0, span, rtol, atol, solver):
    """``d q_0(span) / d beta`` at ``beta = 0.02``: by reverse mode through the simulation
    (diffrax's checkpointed adjoint) and by central differences."""

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
            solver=solver,
        )
        return traj.q[-1, 0]

    beta = jnp.asarray(0.02)
    grad = jax.jit(jax.grad(first_coordinate))(beta)
    h = 1e-5
    fd = (first_coordinate(beta + h) - first_coordinate(beta - h)) / (2 * h)
    return float(grad), float(fd)


@pytest.mark.long(minutes=1.5)
@pytest.mark.slow
def test_gradient_of_a_small_trajectory_matches_finite_differences():
    """The smallest scene with everything the damping enters: one constant-curvature segment
    under gravity and an end mass, with two length-mode tendons held taut (2.5-20 N) whose
    motors' derivative gains are the damping's (``kappa_D = beta kappa_P``), released from
    0.05 rad; 0.1 s. Its fastest mode is not stiff, so an explicit solver integrates it (277
    steps) and its reverse mode compiles in about 75 s on 2 cores, where Kvaerno5's took 416 s
    without the tendons; Rosenbrock23's own derivative is checked in ``test_rosenbrock.py``.
    Where a tendon goes slack and taut during the motion the two differ by 1.9e-5 relative:
    the tension's kink makes the discrete trajectory not smooth in the parameters."""
    scene = small_scene(order=0, quadrature_points=2)
    q0 = jnp.zeros(scene.n_dofs).at[0].set(0.05)
    taut = jnp.array([0.01, 0.01])
    grad, fd = _damping_gradient(scene, taut, q0, 0.1, 1e-9, 1e-11, diffrax.Tsit5())
    assert abs(fd) > 1.0  # the damping matters at this time
    assert abs(grad - fd) < 1e-6 * abs(fd)
