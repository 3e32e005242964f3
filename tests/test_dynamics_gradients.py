"""Gradients through a simulated trajectory (CI's slow step): reverse mode through diffrax's
checkpointed adjoint against central differences. Split from ``test_dynamics.py`` so that a
parallel run can give its minutes of compilation to another worker."""

import diffrax
import jax
import jax.numpy as jnp
import pytest
from dynamics_scenes import CONTROLS, HANGING, SCENE

import pacjax as pj


def _damping_gradient(scene, controls, span, rtol, atol, solver=None):
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
            solver=solver,
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


@pytest.mark.long(minutes=1.5)
@pytest.mark.slow
def test_gradient_of_a_small_trajectory_matches_finite_differences():
    """The same on the smallest scene with everything the damping enters: one
    constant-curvature segment released under gravity and an end mass, 0.1 s. Its fastest mode
    (the axial one, 37 Hz) is not stiff, so an explicit solver integrates it in 111 steps and its
    reverse mode compiles in 76 s on 2 cores, where Kvaerno5's took 416 s in CI's slow step; the
    Rosenbrock solver's own derivative is checked in ``test_rosenbrock.py``, the implicit
    solvers' is diffrax's. The shared scene's version above has not finished on 2 cores."""
    segment = pj.Segment(0.15, 0.02, 600.0, linear_density=0.3, radius=0.012)
    scene = pj.Scene(
        pj.Robot([segment], base_rotation=HANGING),
        pj.PolynomialCurvature(order=0),
        loads=(pj.Gravity(), pj.PointMass(0.03, 0, 1.0)),
        quadrature_points=2,
    )
    grad, fd = _damping_gradient(scene, None, 0.1, rtol=1e-9, atol=1e-11, solver=diffrax.Tsit5())
    assert abs(fd) > 1.0  # the damping matters at this time
    assert abs(grad - fd) < 1e-6 * abs(fd)
