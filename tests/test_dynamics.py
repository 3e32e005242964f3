"""Dynamics: inertia by autodiff, consistency with statics, modal frequencies, damping, input
checks.

One small scene structure (``dynamics_scenes.SCENE``: one segment, linear polynomial curvature,
4 Gauss points, gravity, an end mass and two length-mode tendons) is shared by the tests, so
that it compiles once for them. The checks:

- (slow) ``M`` is the Hessian of the kinetic energy in ``qdot``; the forward-mode Coriolis
  forces equal the Lagrangian reference and the Christoffel form of ``dM/dq``;
- (slow) at rest velocity the dynamic forces are minus the static residual (motor law =
  statics);
- a slack tendon cannot push; the material damping is Kelvin-Voigt;
- the first bending frequency of a uniform cantilever matches Euler-Bernoulli within 2 %.

Motion over time is in ``test_dynamics_motion.py``, gradients through a trajectory in
``test_dynamics_gradients.py``.
"""

import math
import os
import subprocess
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from dynamics_scenes import CONTROLS, SCENE, cantilever, small_scene

import pacjax as pj
from pacjax import dynamics as dyn
from pacjax._dynamics.equations import EquationsOfMotion
from pacjax._model.inertia import (
    body_dynamics,
    chained_body_dynamics,
    coriolis_forces,
    kinetic_energy,
    mass_matrix,
    structured_body_dynamics,
)
from pacjax._model.inputs import as_traced_leaves

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


def _mixed_body():
    """Three segments of mixed polynomial orders (pinned coefficients) with twist, a tapered
    hollow one, an inextensible one (pinned ``dL``), point masses inside segments, a turned and
    moved base."""
    segments = [
        pj.Segment(
            0.1, 0.02, 500.0, linear_density=0.3, radius=0.012, radius_tip=0.008, inner_radius=0.004
        ),
        pj.Segment(0.08, 0.015, 400.0, linear_density=0.2, radius=0.01, extensible=False),
        pj.Segment(0.06, 0.01, 300.0, linear_density=0.1, radius=0.008),
    ]
    axis, angle = np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0), 2.5  # an oblique, hanging base
    skew = np.cross(np.eye(3), axis)
    turn = np.eye(3) + math.sin(angle) * skew + (1.0 - math.cos(angle)) * skew @ skew
    robot = pj.Robot(segments, base_rotation=turn, base_position=(0.01, -0.02, 0.3))
    models = tuple(pj.PolynomialCurvature(k, twist=True) for k in (1, 2, 0))
    loads = (pj.Gravity(), pj.PointMass(0.02, 0, 0.4), pj.PointMass(0.05, 2, 1.0))
    return pj.Scene(robot, models, loads=loads, quadrature_points=5)


@pytest.mark.slow  # 6-12 s of compiling each
@pytest.mark.parametrize("body", ["paper", "mixed"])
def test_structured_inertia_equals_the_chained_kinematics(body):
    """``M`` and ``C qdot`` from the segments' local Jacobians (what the simulator uses) equal
    forward derivatives of the whole chained kinematics, on the paper's robot with PAC and on
    a body with every kind of segment and mass point."""
    if body == "paper":
        scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
    else:
        scene = _mixed_body()
    scene = as_traced_leaves(scene, jnp.float64)
    rng = np.random.default_rng(3)
    q = jnp.asarray(rng.normal(size=scene.n_dofs) * 0.5)
    qdot = jnp.asarray(rng.normal(size=scene.n_dofs))

    @jax.jit
    def both(q, qdot):
        return structured_body_dynamics(scene, q, qdot), chained_body_dynamics(scene, q, qdot)

    (mass, bias), (mass_ref, bias_ref) = both(q, qdot)
    np.testing.assert_allclose(mass, mass_ref, rtol=0, atol=1e-13 * float(jnp.abs(mass_ref).max()))
    np.testing.assert_allclose(bias, bias_ref, rtol=0, atol=1e-12 * float(jnp.abs(bias_ref).max()))


@pytest.mark.slow  # compiles second and third derivatives of the kinematics
def test_rest_velocity_recovers_statics():
    """M qddot = -F(q) at qdot = 0: the motor PD law reduces to the statics' tendon tension."""
    zero = jnp.zeros(SCENE.n_dofs)
    qddot = jax.jit(lambda q: dyn.accelerations(SCENE, q, zero, CONTROLS))(Q)
    mass = jax.jit(lambda q: mass_matrix(SCENE, q))(Q)
    residual = jax.jit(lambda q: SCENE.residual(q, CONTROLS))(Q)  # op by op: 450 programs
    assert jnp.max(jnp.abs(mass @ qddot + residual)) < 1e-9 * jnp.max(jnp.abs(residual))


def test_slack_tendon_cannot_push():
    """A tendon longer than its commanded length does nothing, whatever the velocity."""
    q = jnp.zeros(SCENE.n_dofs)
    qdot = jnp.zeros(SCENE.n_dofs).at[0].set(5.0)  # bending fast: one tendon shortens
    controls = jnp.array([-0.01, -0.01])  # commands longer than the rest lengths: both slack
    model = EquationsOfMotion.build(SCENE, pj.Damping(stiffness=0.05), 1e-6, q.dtype)
    # One program for the three calls (op by op they compiled 400 small ones).
    tendon_forces = eqx.filter_jit(lambda m, *args: m.tendon_forces(*args))
    force = tendon_forces(model, q, qdot, controls, jnp.zeros(2))
    assert jnp.all(force == 0.0)
    # taut and stretching: the derivative gain adds to the pull
    taut = tendon_forces(model, q, qdot, jnp.array([0.001, 0.001]), jnp.zeros(2))
    still = tendon_forces(model, q, jnp.zeros_like(qdot), jnp.array([0.001, 0.001]), jnp.zeros(2))
    assert jnp.max(jnp.abs(taut - still)) > 0


def test_forces_are_the_passive_potential_and_the_motor_law():
    """``forces`` takes the tendons' pull as one gradient of the potential with the statics'
    springs pulling as the motors do: it equals the passive potential's gradient plus the motor
    law written out (:meth:`EquationsOfMotion.tendon_forces`), a tendon taut and stretching,
    one slack, one in tension mode, the commands moving."""
    tendons = (
        *SCENE.tendons,
        pj.Tendon(0, math.pi / 2, 0.01, mode="tension"),
    )
    scene = pj.Scene(SCENE.robot, SCENE.models, tendons=tendons, loads=SCENE.loads)
    model = EquationsOfMotion.build(scene, pj.Damping(stiffness=0.05), 1e-6, Q.dtype)
    controls = jnp.array([0.08, -0.01, 0.5])
    rates = jnp.array([0.03, -0.02, 0.0])
    zero_mass = jnp.zeros((scene.n_dofs, scene.n_dofs))

    def both(m, q, qdot):
        fused = m.forces(q, qdot, controls, rates, zero_mass)
        written = (
            -jax.grad(m.passive.potential_energy)(q, controls)
            + m.tendon_forces(q, qdot, controls, rates)
            - m.damping.stiffness * m.material_damping(q, qdot)
        )
        return fused, written

    fused, written = eqx.filter_jit(both)(model, Q, QDOT)
    np.testing.assert_allclose(
        fused, written, rtol=1e-12, atol=1e-12 * float(jnp.max(jnp.abs(written)))
    )
    tensions = model._motor_law(
        scene.tendon_lengths(Q), jax.jvp(scene.tendon_lengths, (Q,), (QDOT,))[1], controls, rates
    )[0]
    assert tensions[0] > 0 and tensions[1] == 0 and tensions[2] == 0.5


@pytest.mark.parametrize("frame", ["torsion_free", "paper"])
def test_material_damping_is_kelvin_voigt(frame):
    """``D(q) = beta J(q)^T K_s J(q)``: ``beta K_0`` at rest, and a bent PCC segment's
    bending-plane angle is damped by the curvature it rotates (it was undamped with the
    constant ``K_0``: a slow swing across the bending plane that lasted seconds)."""
    segment = pj.Segment(0.12, 0.02, 800.0, linear_density=0.3)
    scene = pj.Scene(pj.Robot([segment]), pj.PCC(frame=frame))
    model = EquationsOfMotion.build(scene, pj.Damping(stiffness=1.0), 1e-6, jnp.float64)
    zero = jnp.zeros(scene.n_dofs)

    # Compiled (op by op the two matrices took ~200 small compilations).
    @jax.jit
    def damping_matrix(q):
        return jax.jacfwd(lambda v: model.material_damping(q, v))(zero)

    k0 = jax.jit(jax.hessian(scene.elastic_energy))(zero)
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


def test_cantilever_first_frequency_matches_euler_bernoulli():
    scene, ei, density, length = cantilever(pj.PolynomialCurvature(order=3), 2)
    expected = 1.8751**2 * math.sqrt(ei / (density * length**4)) / (2 * math.pi)
    freqs = np.asarray(dyn.natural_frequencies(scene))
    # two bending planes: the lowest pair is the first bending mode
    assert abs(freqs[0] / expected - 1) < 0.02
    assert abs(freqs[1] / expected - 1) < 0.02
    assert freqs[2] > 5 * expected  # the next mode is the second bending mode


def test_input_validation():
    with pytest.raises(ValueError, match="linear_density"):
        pj.simulate(small_scene(density=0.0), (0.0, 1.0))
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
    for dt0 in (-1e-3, 0.0, 2.0, float("nan")):
        with pytest.raises(ValueError, match="dt0"):
            pj.simulate(SCENE, (0.0, 1.0), dt0=dt0)


def test_simulations_at_control_tolerances_take_the_dynamics_knot_grid():
    """At ``rtol >= ROSENBROCK_RTOL`` a PCC/PAC scene that sets no knot grid is simulated on
    :data:`pacjax.dynamics.KNOT_GRID` (its frames within ``tests/test_kinematics.py``'s bounds
    of the statics' grid), a ``PolynomialCurvature`` one (its rotation by Magnus steps on the
    intervals) on the statics' intervals with the three nodes; a reference tolerance, or a grid
    the scene sets, keeps the scene's."""
    from pacjax._dynamics.simulate import ROSENBROCK_RTOL, prepare

    def grid(scene, rtol):
        args = (0.0, 0.1, None, pj.Damping(), None, rtol, 1e-6, 100, False, 1e-6, None)
        return prepare(scene, *args)[0].knot_grid

    pac = pj.presets.stella2023(pj.PAC())
    assert grid(pac, dyn.RTOL) == grid(pac, ROSENBROCK_RTOL) == dyn.KNOT_GRID == (4, 3)
    assert isinstance(SCENE.model, pj.PolynomialCurvature)
    assert grid(SCENE, dyn.RTOL) == (8, 3)
    assert grid(pac, ROSENBROCK_RTOL / 10) is grid(SCENE, ROSENBROCK_RTOL / 10) is None
    assert grid(SCENE.replace(knot_grid=(8, 4)), dyn.RTOL) == (8, 4)


@pytest.mark.slow  # a fresh Python process that compiles a simulation (17 s): CI's slow step
def test_a_simulation_can_be_kept_in_the_compilation_cache():
    """JAX's persistent cache stores no program that calls back into Python. diffrax checks the
    save times with equinox's runtime errors, callbacks unless ``EQX_ON_ERROR=nan`` (which
    the command line sets; equinox reads it as it is imported): then ``simulate``'s program
    holds none."""
    code = """
import numpy as np, pacjax as pj
from pacjax._dynamics import simulate as sim
seg = pj.Segment(0.2, 1e-2, 1e3, linear_density=0.1)
scene = pj.Scene(pj.Robot([seg]), pj.PCC(), loads=[pj.Gravity()])
scene, damping, opts, span, ts = sim.prepare(
    scene, 0.0, 0.1, None, None, None, sim.RTOL, sim.ATOL, 100, False, sim.PHI_INERTIA_FACTOR, None
)
q, u = np.zeros(scene.n_dofs), np.zeros(0)
text = sim.integrate.lower(scene, damping, u, q, q, span, ts, None, opts).as_text()
print(text.count("callback"))
"""
    counts = {}
    for mode in ("raise", "nan"):
        env = dict(os.environ, EQX_ON_ERROR=mode)
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        counts[mode] = int(out.stdout.split()[-1])
    assert counts["raise"] > 0  # the check is real: diffrax's callbacks are there by default
    assert counts["nan"] == 0


@pytest.mark.slow  # a float32 copy of every dynamics program: CI's slow step
@pytest.mark.parametrize("damping", [None, pj.Damping(stiffness=1e-3)], ids=["modal", "given"])
def test_a_float32_scene_simulates_in_float32(damping):
    """Found by the campaign: ``Damping()``'s zero mass coefficient was a float64 array, which
    promoted a float32 scene's forces to float64, and lineax refused to solve them with the
    float32 mass matrix (the default damping and a given one alike)."""
    scene = pj.astype(small_scene(order=0, quadrature_points=2), jnp.float32)
    traj = pj.simulate(scene, (0.0, 0.005), CONTROLS, damping=damping, rtol=1e-3, atol=1e-5)
    assert bool(traj.successful)
    assert traj.q.dtype == jnp.float32
    assert np.all(np.isfinite(np.asarray(traj.q)))
