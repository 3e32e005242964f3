"""The horizontal cantilever against linear beam theory and the (inextensible) elastica.

Clamped at the origin along world +x (base rotation taking +z to +x), gravity along world -z.
References, independent of pacjax:

- linear beam theory: tip deflection ``P L^3 / (3 EI)``, slope ``P L^2 / (2 EI)`` for a tip load,
  ``w L^4 / (8 EI)`` for self-weight;
- the elastica, solved here by shooting on ``theta'' = -(alpha + beta (1 - s)) cos(theta)``
  (``theta`` the slope, downward positive, ``s`` the arc length over ``L``; ``theta(0) = 0``,
  ``theta'(1) = 0``; ``alpha = P L^2 / EI``, ``beta = w L^3 / EI``) with fixed-step RK4 in numpy;
- a follower force normal to the tip: the force is constant along the rod, so the same ODE with
  the load direction ``theta(1)`` unknown, ``theta'' = -alpha cos(theta - theta(1))``.

Inextensibility: ``k_a = EA / L_i`` per segment with ``EA = 1e8 EI / L^2``, so the rod
stretches by at most ``max|N| L / EA = alpha / 1e8 L`` (1e-7 L at ``alpha = 10``), far below the
tolerances; the tests check the elongation too.
"""

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from checks import scaled_residual
from marks import slow

import pacjax as pj

LENGTH = 1.0  # m
EI = 1.0  # N m^2
EA = 1.0e8 * EI / LENGTH**2  # N
G = 9.81  # m/s^2
# Base frame -> world: the rest axis +z becomes world +x, the section's x axis world -z (down).
HORIZONTAL = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
ELASTICA_TOL = 1e-3 * LENGTH  # the acceptance tolerance

# (alpha, beta) -> (tip deflection / L, shortening / L), the classical values.
CLASSICAL = {
    (1.0, 0.0): (0.30172, 0.056433),
    (10.0, 0.0): (0.81061, 0.55500),
    (0.0, 1.0): (0.12347, 0.0087536),
}


# ------------------------------------------------------------------------------ references
def _rk4(rhs, y0, steps):
    h = 1.0 / steps
    y, s = np.asarray(y0, float), 0.0
    for _ in range(steps):
        k1 = rhs(s, y)
        k2 = rhs(s + h / 2, y + h / 2 * k1)
        k3 = rhs(s + h / 2, y + h / 2 * k2)
        k4 = rhs(s + h, y + h * k3)
        y, s = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), s + h
    return y


def _shoot(residual, x0, tol=1e-13):
    """Newton with a finite-difference Jacobian on the shooting unknowns."""
    x = np.asarray(x0, float)
    for _ in range(50):
        r = residual(x)
        if np.max(np.abs(r)) < tol:
            return x
        jac = np.stack([(residual(x + 1e-7 * e) - r) / 1e-7 for e in np.eye(len(x))], axis=1)
        x = x - np.linalg.solve(jac, r)
    raise RuntimeError("shooting did not converge")


@functools.lru_cache
def elastica_reference(alpha, beta, steps=1000):
    """Clamped inextensible cantilever under a vertical tip load ``alpha = P L^2 / EI`` and
    self-weight ``beta = w L^3 / EI``: ``(deflection, shortening, tip slope)``, lengths over L.
    RK4 with 1000 steps: error ~1e-13."""

    def run(k0):
        def rhs(s, y):  # y = (theta, theta', x, z_down)
            th = y[0]
            return np.array(
                [y[1], -(alpha + beta * (1 - s)) * math.cos(th), math.cos(th), math.sin(th)]
            )

        return _rk4(rhs, [0.0, k0, 0.0, 0.0], steps)

    (k0,) = _shoot(lambda x: run(x[0])[1:2], [alpha + beta / 2])
    th, _, x, z = run(k0)
    return z, 1.0 - x, th


@functools.lru_cache
def follower_reference(alpha, steps=1000):
    """Cantilever with a tip force ``alpha EI / L^2`` that stays normal to the tip:
    ``(deflection, shortening, tip slope)``."""

    def run(x):
        k0, tip = x

        def rhs(s, y):
            return np.array([y[1], -alpha * math.cos(y[0] - tip), math.cos(y[0]), math.sin(y[0])])

        return _rk4(rhs, [0.0, k0, 0.0, 0.0], steps)

    def residual(x):
        y = run(x)
        return np.array([y[1], y[0] - x[1]])

    x = _shoot(residual, [alpha, alpha / 2])
    th, _, xx, z = run(x)
    return z, 1.0 - xx, th


def test_elastica_reference_matches_classical_values():
    """The shooting solution reproduces the classical table to its printed digits and is
    converged in the number of RK4 steps."""
    for (alpha, beta), (deflection, shortening) in CLASSICAL.items():
        z, short, _ = elastica_reference(alpha, beta)
        z_fine, short_fine, _ = elastica_reference(alpha, beta, steps=4000)
        assert abs(z - z_fine) < 1e-11 and abs(short - short_fine) < 1e-11
        digits = 10.0 ** (math.floor(math.log10(shortening)) - 4)  # 5 significant digits
        assert abs(z - deflection) <= 0.5e-5 + 1e-12
        assert abs(short - shortening) <= 0.5 * digits + 1e-12
    # Linear limit: alpha -> 0 gives alpha / 3.
    z, _, slope = elastica_reference(1e-4, 0.0)
    np.testing.assert_allclose([z, slope], [1e-4 / 3, 1e-4 / 2], rtol=1e-8)
    # Follower: the tip slope satisfies the first integral int_0^tip du / sqrt(2 alpha sin u) = 1
    # (midpoint rule after u = tip v^2, which removes the end singularity).
    _, _, tip = follower_reference(1.0)
    v = (np.arange(200000) + 0.5) / 200000
    integral = np.mean(2 * tip * v / np.sqrt(2 * np.sin(tip * v**2)))
    np.testing.assert_allclose(integral, 1.0, rtol=1e-6)


# ------------------------------------------------------------------------------ scenes
def cantilever(n_segments, tip_force=0.0, weight=0.0, order=3, quadrature_points=8):
    """The uniform cantilever: ``n_segments`` equal segments, a world-fixed tip force
    ``tip_force`` (N, downward) and self-weight ``weight`` (N/m). One structure per
    ``(n_segments, order, quadrature_points)``, whatever the loads' values."""
    segment = pj.Segment(
        LENGTH / n_segments,
        bending_stiffness=EI,
        axial_stiffness=EA * n_segments / LENGTH,
        linear_density=weight / G,
    )
    loads = (
        pj.Gravity(G),
        pj.PointForce(np.array([0.0, 0.0, -tip_force]), n_segments - 1, 1.0),
    )
    robot = pj.Robot([segment] * n_segments, base_rotation=HORIZONTAL)
    return pj.Scene(
        robot, pj.PolynomialCurvature(order), loads=loads, quadrature_points=quadrature_points
    )


def solve_tip(scene, **kwargs):
    """Equilibrium, tip deflection / L, shortening / L, tip slope (rad, downward)."""
    eq = pj.solve_equilibrium(scene, **kwargs)
    assert bool(eq.converged), (eq.reason, float(eq.residual_norm))
    pos, rot = pj.tip_pose(scene, eq.q)
    pos, rot = np.asarray(pos), np.asarray(rot)
    assert abs(pos[1]) < 1e-12  # stays in the vertical xz plane
    tangent = rot[:, 2]
    return eq, -pos[2] / LENGTH, 1.0 - pos[0] / LENGTH, math.atan2(-tangent[2], tangent[0])


def total_elongation(scene, q):
    return float(np.sum(np.asarray(scene.coordinates(q))[:, -1]))


# ------------------------------------------------------------------------------ linear limit
@pytest.mark.parametrize("n_segments", [1, slow(2)])
def test_small_tip_load_matches_linear_beam_theory(n_segments):
    alpha = 0.03  # nonlinearity: the elastica's deflection is 1.0e-4 relative below alpha / 3
    load = alpha * EI / LENGTH**2
    _, deflection, _, slope = solve_tip(cantilever(n_segments, tip_force=load))
    linear = load * LENGTH**3 / (3 * EI) / LENGTH
    np.testing.assert_allclose(deflection, linear, rtol=5e-3)
    np.testing.assert_allclose(slope, load * LENGTH**2 / (2 * EI), rtol=5e-3)
    # Tighter: the difference from linear theory is exactly the elastica's nonlinearity.
    z, _, th = elastica_reference(alpha, 0.0)
    np.testing.assert_allclose([deflection, slope], [z, th], rtol=1e-7)
    assert abs(deflection / linear - 1.0) < 1e-3


@pytest.mark.parametrize("n_segments", [1, slow(2)])
def test_small_self_weight_matches_linear_beam_theory(n_segments):
    beta = 0.03
    weight = beta * EI / LENGTH**3
    _, deflection, _, _ = solve_tip(cantilever(n_segments, weight=weight))
    linear = weight * LENGTH**4 / (8 * EI) / LENGTH
    np.testing.assert_allclose(deflection, linear, rtol=5e-3)
    z, _, _ = elastica_reference(0.0, beta)
    np.testing.assert_allclose(deflection, z, rtol=1e-7)


# ------------------------------------------------------------------------------ elastica
@pytest.mark.parametrize("alpha, beta", list(CLASSICAL), ids=["tip1", "tip10", "weight1"])
def test_large_deflection_matches_elastica(alpha, beta):
    """PolynomialCurvature(3), 4 segments, float64: within 1e-3 L of the elastica (measured
    ~1e-7 L); the rod is effectively inextensible."""
    scene = cantilever(4, tip_force=alpha * EI / LENGTH**2, weight=beta * EI / LENGTH**3)
    eq, deflection, shortening, _ = solve_tip(scene)
    z, short, _ = elastica_reference(alpha, beta)
    assert abs(deflection - z) * LENGTH < ELASTICA_TOL
    assert abs(shortening - short) * LENGTH < ELASTICA_TOL
    # Against the classical table as quoted, too.
    expected = CLASSICAL[(alpha, beta)]
    assert abs(deflection - expected[0]) * LENGTH < ELASTICA_TOL
    assert abs(shortening - expected[1]) * LENGTH < ELASTICA_TOL
    # A tighter guard on the converged discretisation (see experiments/convergence).
    assert max(abs(deflection - z), abs(shortening - short)) < 1e-5
    assert abs(total_elongation(scene, eq.q)) < 1e-6 * LENGTH
    assert bool(eq.stable)


@pytest.mark.slow  # a convergence study (~25-35 s): CI's slow step
def test_segment_chaining_converges():
    """The same rod as 1, 2 and 4 segments: the answers converge (to the elastica) as segments
    are added, and in the linear regime, where the exact curvature is a polynomial every split
    represents, all splits agree to the solver tolerance. The small load's solves run at tol
    1e-12: the rod's softest scaled mode is 4.8e-4, so a residual just inside the default 1e-10
    (8.4e-11, 4 segments) leaves a relative error of 5e-8 in the deflection."""
    alpha = 10.0
    z, short, _ = elastica_reference(alpha, 0.0)
    errors, small = [], []
    for n in (1, 2, 4):
        _, deflection, shortening, _ = solve_tip(cantilever(n, tip_force=alpha * EI / LENGTH**2))
        errors.append(max(abs(deflection - z), abs(shortening - short)))
        small_load = cantilever(n, tip_force=1e-3 * EI / LENGTH**2)
        _, d_small, s_small, _ = solve_tip(small_load, tol=1e-12)
        small.append([d_small, s_small])
    assert errors[0] < ELASTICA_TOL
    assert errors[2] < errors[1] < errors[0], errors
    np.testing.assert_allclose(small, np.broadcast_to(small[0], (3, 2)), rtol=1e-8, atol=1e-14)


@pytest.mark.slow
def test_pcc_chain_converges_to_elastica():
    """Constant curvature per segment: the chain converges to the elastica at second order."""
    alpha = 1.0
    errors = [
        elastica_error(cantilever(n, tip_force=alpha * EI / LENGTH**2, order=0), alpha)
        for n in (2, 4, 8)
    ]
    ratios = np.asarray(errors[:-1]) / np.asarray(errors[1:])
    assert np.all((ratios > 3.0) & (ratios < 5.0)), (errors, ratios)
    assert errors[-1] < 2e-3


def elastica_error(scene, alpha, beta=0.0):
    _, deflection, shortening, _ = solve_tip(scene)
    z, short, _ = elastica_reference(alpha, beta)
    return max(abs(deflection - z), abs(shortening - short))


@pytest.mark.slow
def test_error_falls_with_polynomial_order():
    """One segment: each extra polynomial order reduces the error (order 3 is also in the fast
    tests; the convergence study has the full table)."""
    for alpha in (1.0, 10.0):
        errors = [
            elastica_error(cantilever(1, tip_force=alpha * EI / LENGTH**2, order=o), alpha)
            for o in (1, 2, 3, 4)
        ]
        assert errors[0] < 3e-2, errors
        assert all(a > b for a, b in zip(errors[:-1], errors[1:], strict=False)), (alpha, errors)


# ------------------------------------------------------------------------------ follower force
FOLLOWER_SEGMENTS = 2


def follower_cantilever(alpha):
    """Tip force ``alpha EI / L^2`` along the tip's local x axis: downward at rest, and it stays
    normal to the tip as the rod bends."""
    segment = pj.Segment(LENGTH / FOLLOWER_SEGMENTS, EI, EA * FOLLOWER_SEGMENTS / LENGTH)
    force = pj.PointForce(
        np.array([alpha * EI / LENGTH**2, 0.0, 0.0]), FOLLOWER_SEGMENTS - 1, 1.0, follower=True
    )
    robot = pj.Robot([segment] * FOLLOWER_SEGMENTS, base_rotation=HORIZONTAL)
    return pj.Scene(robot, pj.PolynomialCurvature(3), loads=(force,))


@pytest.mark.parametrize("alpha", [1.0, 3.0])
def test_follower_force_differs_from_fixed_force_and_matches_reference(alpha):
    scene = follower_cantilever(alpha)
    eq, deflection, shortening, slope = solve_tip(scene)

    # The follower elastica (force normal to the tip).
    z, short, tip = follower_reference(alpha)
    np.testing.assert_allclose([deflection, shortening, slope], [z, short, tip], atol=1e-5)

    # Equilibrium: the generalised residual vanishes at the returned q ...
    assert float(scaled_residual(scene, eq.q)) < 1e-9
    # ... and the force has turned with the tip: still normal to the tangent.
    _, rot = pj.tip_pose(scene, eq.q)
    world_force = np.asarray(rot) @ np.asarray(scene.loads[0].force)
    assert abs(world_force @ np.asarray(rot)[:, 2]) < 1e-9 * np.linalg.norm(world_force)
    np.testing.assert_allclose(
        world_force / np.linalg.norm(world_force), [-math.sin(tip), 0.0, -math.cos(tip)], atol=1e-5
    )

    # A world-fixed force equal to that final force has the same equilibrium (same rod) ...
    fixed = cantilever(FOLLOWER_SEGMENTS)
    fixed = eqx.tree_at(lambda s: s.loads[1].force, fixed, jnp.asarray(world_force))
    eq_same, d_same, s_same, _ = solve_tip(fixed, q0=eq.q)
    np.testing.assert_allclose([d_same, s_same], [deflection, shortening], atol=1e-9)
    # ... while the load held vertical (its rest direction) gives a different one.
    _, d_fixed, s_fixed, _ = solve_tip(cantilever(FOLLOWER_SEGMENTS, tip_force=alpha))
    z_fixed, short_fixed, _ = elastica_reference(alpha, 0.0)
    np.testing.assert_allclose([d_fixed, s_fixed], [z_fixed, short_fixed], atol=1e-5)
    assert abs(deflection - d_fixed) > 0.01 and abs(shortening - s_fixed) > 0.005


def test_follower_residual_jacobian_matches_finite_differences():
    """The Jacobian the solver (and the implicit-function-theorem gradient) uses is the
    derivative of the residual, including the turning of the follower force with the body."""
    scene = follower_cantilever(3.0)
    controls = scene.default_controls()
    q = np.random.default_rng(0).normal(0.0, 0.3, (FOLLOWER_SEGMENTS, scene.dofs_per_segment))
    q[:, -1] = 0.0  # no elongation
    q = jnp.asarray(q.reshape(-1))
    residual = jax.jit(lambda q: scene.residual(q, controls))
    jac = np.asarray(jax.jit(jax.jacfwd(lambda q: scene.residual(q, controls)))(q))
    h = 1e-6
    fd = np.stack(
        [(residual(q + h * e) - residual(q - h * e)) / (2 * h) for e in jnp.eye(scene.n_dofs)],
        axis=1,
    )
    bending = np.abs(np.diag(fd)).min()  # the smallest elastic stiffness, EI / L_i scale
    np.testing.assert_allclose(jac, fd, atol=1e-6 * bending)


@pytest.mark.slow
def test_follower_implicit_gradient_matches_finite_differences():
    """d(tip deflection)/d(load) through the implicit function theorem."""

    def deflection(load):
        scene = eqx.tree_at(
            lambda s: s.loads[0].force, follower_cantilever(1.0), jnp.stack([load, 0.0, 0.0])
        )
        eq = pj.solve_equilibrium(scene, fallback=False)
        return -pj.tip_pose(scene, eq.q)[0][2]

    grad = jax.grad(deflection)(1.0)
    h = 1e-5
    fd = (deflection(1.0 + h) - deflection(1.0 - h)) / (2 * h)
    np.testing.assert_allclose(grad, fd, rtol=1e-6)
