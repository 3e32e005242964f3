"""Bodies as labs build them: material and taper, rest curvature, a strain model per segment,
inextensible segments (each against a closed form or an independent reference)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from marks import slow
from scipy.integrate import quad, solve_ivp
from scipy.optimize import brentq

import pacjax as pj
from pacjax._model.hessian import energy_derivatives
from pacjax.io.scenefile import scene_from_toml, scene_to_toml

E, RHO, R0, R1, LENGTH = 2.0e6, 1100.0, 0.012, 0.006, 0.3
HORIZONTAL = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])


@eqx.filter_jit  # once per scene structure (op by op: ~100 small compilations a scene)
def _energy(scene, q):
    return scene.potential_energy(q, scene.default_controls(q.dtype))


@eqx.filter_jit  # once per scene structure (op by op: 40-120 small compilations a scene)
def _energy_and_residual(scene, q):
    controls = scene.default_controls(q.dtype)
    return scene.potential_energy(q, controls), scene.residual(q, controls)


def _tapered_pieces(n, **kwargs):
    """A linear taper R0 -> R1 over LENGTH cut into ``n`` segments from material values."""
    radii = np.linspace(R0, R1, n + 1)
    return [
        pj.Segment.from_material(
            LENGTH / n, young_modulus=E, density=RHO, radius=a, radius_tip=b, **kwargs
        )
        for a, b in zip(radii[:-1], radii[1:], strict=True)
    ]


def _second_moment(x):
    r = R0 + (R1 - R0) * x / LENGTH
    return np.pi * r**4 / 4


def test_material_values_of_a_hollow_taper():
    seg = pj.Segment.from_material(
        0.2,
        young_modulus=E,
        density=RHO,
        radius=0.01,
        radius_tip=0.005,
        inner_radius=0.004,
        inner_radius_tip=0.002,
        poisson=0.3,
    )
    area = lambda s: np.pi * ((0.01 - 0.005 * s) ** 2 - (0.004 - 0.002 * s) ** 2)  # noqa: E731
    compliance = quad(lambda s: 0.2 / (E * area(s)), 0, 1, epsabs=1e-16, epsrel=1e-13)[0]
    np.testing.assert_allclose(seg.axial_stiffness, 1.0 / compliance, rtol=1e-12)
    np.testing.assert_allclose(seg.bending_stiffness, E * np.pi * (0.01**4 - 0.004**4) / 4)
    np.testing.assert_allclose(seg.torsion_stiffness, seg.bending_stiffness / 1.3)
    np.testing.assert_allclose(seg.linear_density, RHO * area(0.0))
    s = np.linspace(0, 1, 5)
    np.testing.assert_allclose(
        seg.bending_profile(s),
        ((0.01 - 0.005 * s) ** 4 - (0.004 - 0.002 * s) ** 4) / (0.01**4 - 0.004**4),
    )
    np.testing.assert_allclose(seg.area_profile(s), area(s) / area(0.0))
    solid = pj.Segment.from_material(0.2, young_modulus=E, radius=0.01, radius_tip=0.005)
    np.testing.assert_allclose(solid.axial_stiffness, E * np.pi * 0.01 * 0.005 / 0.2, rtol=1e-14)
    uniform = pj.Segment.from_material(0.2, young_modulus=E, radius=0.01)
    np.testing.assert_allclose(uniform.axial_stiffness, E * np.pi * 0.01**2 / 0.2, rtol=1e-14)
    # Differentiable in the material values (identification fits E).
    grad = jax.grad(
        lambda e: (
            pj.Segment.from_material(
                0.2, young_modulus=e, radius=0.01, radius_tip=0.005
            ).axial_stiffness
        )
    )(E)
    np.testing.assert_allclose(grad, np.pi * 0.01 * 0.005 / 0.2, rtol=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        (dict(inner_radius=0.02), "inner_radius"),
        (dict(inner_radius=0.004, inner_radius_tip=0.007, radius_tip=0.006), "inner_radius"),
        (dict(poisson=0.7), "poisson"),
        (dict(young_modulus=-1.0), "young_modulus"),
    ],
)
def test_material_values_are_checked(kwargs, field):
    args = dict(young_modulus=E, radius=0.01) | kwargs
    with pytest.raises(ValueError, match=field):
        pj.Segment.from_material(0.2, **args)


def test_axial_stiffness_of_a_linear_taper_under_an_end_load():
    force = 0.05
    scene = pj.Scene(
        pj.Robot(_tapered_pieces(3), base_rotation=HORIZONTAL),
        pj.PolynomialCurvature(1),
        loads=[pj.PointForce(np.array([force, 0.0, 0.0]), 2)],
    )
    eq = pj.solve_equilibrium(scene)
    tip = np.asarray(pj.markers(scene, eq.q, [(2, 1.0)]))[0]
    expected = force * LENGTH / (E * np.pi * R0 * R1)  # int dx / (E A(x)) of the whole taper
    np.testing.assert_allclose(tip[0] - LENGTH, expected, rtol=1e-9)


@pytest.mark.slow  # an accuracy study against a closed form (~18 s): CI's slow step
def test_tapered_cantilever_small_load_against_the_closed_form():
    force = 1e-6  # tip deflection ~1e-4 of the length: linear theory to ~1e-8
    scene = pj.Scene(
        pj.Robot(_tapered_pieces(6, extensible=False), base_rotation=HORIZONTAL),
        pj.PolynomialCurvature(3),
        loads=[pj.PointForce(np.array([0.0, 0.0, -force]), 5)],
        quadrature_points=8,
    )
    eq = pj.solve_equilibrium(scene)
    assert eq.converged
    tip = np.asarray(pj.markers(scene, eq.q, [(5, 1.0)]))[0]
    closed = force * quad(lambda x: (LENGTH - x) ** 2 / (E * _second_moment(x)), 0, LENGTH)[0]
    np.testing.assert_allclose(-tip[2], closed, rtol=1e-6)  # measured 8.6e-9


def _tapered_elastica(force):
    """Tip of an inextensible tapered cantilever (horizontal, along +x) under a dead tip force
    ``-force`` along z: ``theta' = M / EI(x)``, ``M = -force (X_tip - X)``, shot from the tip."""

    def rhs(x, y):  # y = (theta, moment); integrated from the tip (moment 0) to the base
        theta, _ = y
        return [y[1] / (E * _second_moment(x)), force * np.cos(theta)]

    def base_angle(theta_tip):
        sol = solve_ivp(rhs, (LENGTH, 0.0), [theta_tip, 0.0], rtol=1e-12, atol=1e-14)
        return sol.y[0, -1]

    theta_tip = brentq(base_angle, -np.pi / 2, 0.0, xtol=1e-15)
    sol = solve_ivp(rhs, (LENGTH, 0.0), [theta_tip, 0.0], rtol=1e-12, atol=1e-14, dense_output=True)
    x = quad(lambda v: np.cos(sol.sol(v)[0]), 0, LENGTH, epsabs=1e-14, limit=200)[0]
    z = quad(lambda v: np.sin(sol.sol(v)[0]), 0, LENGTH, epsabs=1e-14, limit=200)[0]
    return np.array([x, z])


@pytest.mark.slow  # a high-resolution reference (18 s): CI's slow step
def test_tapered_cantilever_large_load_against_a_high_resolution_reference():
    force = 0.2  # the tip drops by 31 % of the length
    # The small-load test's scene structure (6 segments, 8 points): its solver is compiled once.
    scene = pj.Scene(
        pj.Robot(_tapered_pieces(6, extensible=False), base_rotation=HORIZONTAL),
        pj.PolynomialCurvature(3),
        loads=[pj.PointForce(np.array([0.0, 0.0, -force]), 5)],
        quadrature_points=8,
    )
    eq = pj.solve_equilibrium(scene)
    assert eq.converged
    tip = np.asarray(pj.markers(scene, eq.q, [(5, 1.0)]))[0]
    reference = _tapered_elastica(force)
    assert reference[1] < -0.3 * LENGTH
    # Measured 7e-9 / 1.1e-8 m with 4 segments, 3.4e-10 / 5.7e-10 m with 6 (4e-11 m with 8).
    np.testing.assert_allclose(tip[[0, 2]], reference, atol=5e-8)


# ------------------------------------------------------------------------------ rest curvature
REST = {
    "PCC": (pj.PCC(), [1.1, 0.4]),
    "PAC": (pj.PAC(), [0.8, -0.6, 2.0]),
    "Poly2": (pj.PolynomialCurvature(2), [0.5, 0.2, -0.3, -0.4, 0.1, 0.6]),
}


@pytest.mark.parametrize("name", sorted(REST))
def test_a_pre_curved_segment_with_no_load_stays_at_rest(name):
    model, rest = REST[name]
    seg = pj.Segment(0.1, 0.01, 200.0, rest_curvature=rest)
    scene = pj.Scene(pj.Robot([seg, seg]), model)
    q_rest = scene.rest_configuration()
    np.testing.assert_array_equal(scene.coordinates(q_rest)[0, :-1], rest)
    energy, residual = _energy_and_residual(scene, q_rest)
    assert float(energy) == 0.0
    np.testing.assert_array_equal(residual, 0.0)
    eq = pj.solve_equilibrium(scene)  # starts at rest
    assert eq.converged and float(eq.energy) == 0.0
    # From straight the same shape (PCC/PAC may find it with the plane turned by pi and the
    # curvatures negated, where the plane angle's regulariser adds its bias of 2 k_phi).
    eq = pj.solve_equilibrium(scene, q0=scene.zeros())
    assert eq.converged
    np.testing.assert_allclose(
        pj.markers(scene, eq.q, [(1, 1.0)]), pj.markers(scene, q_rest, [(1, 1.0)]), atol=1e-10
    )


@pytest.mark.parametrize(
    "model",
    [slow(pj.PCC()), pj.PAC(), slow(pj.PolynomialCurvature(2))],
    ids=["PCC", "PAC", "Poly2"],
)
def test_pure_end_moment_on_a_pre_curved_segment_gives_the_circle(model):
    ei, length, kappa0, moment = 0.02, 0.15, 4.0, 0.004  # kappa0 in 1/m
    own = {3: [kappa0 * length, 0.0], 4: [kappa0 * length, 0.0, 0.0]}
    rest = own.get(model.dofs_per_segment(), [kappa0 * length, 0, 0, 0, 0, 0])
    seg = pj.Segment(length, ei, 500.0, rest_curvature=rest, extensible=False)
    # A moment about the body's +y bends towards +x (the rest curvature's side).
    scene = pj.Scene(
        pj.Robot([seg]), model, loads=[pj.PointMoment(np.array([0.0, moment, 0.0]), 0)]
    )
    eq = pj.solve_equilibrium(scene)
    assert eq.converged
    kappa = kappa0 + moment / ei
    tip = np.asarray(pj.markers(scene, eq.q, [(0, 1.0)]))[0]
    circle = np.array([(1 - np.cos(kappa * length)) / kappa, 0.0, np.sin(kappa * length) / kappa])
    np.testing.assert_allclose(tip, circle, atol=1e-12)


def _hanging_cable(kappa0, ei, w, length, sites):
    """Positions (horizontal, vertical) of an inextensible cable clamped hanging down, with
    rest curvature ``kappa0`` (1/m) towards +x and weight ``w`` (N/m): ``psi`` from the
    downward vertical, ``psi' = kappa0 + m / EI``, ``m' = w (L - x) sin psi``, ``m(L) = 0``,
    ``psi(0) = 0`` (shot from the tip)."""

    def rhs(x, y):
        return [kappa0 + y[1] / ei, w * (length - x) * np.sin(y[0])]

    def base_angle(psi_tip):
        return solve_ivp(rhs, (length, 0.0), [psi_tip, 0.0], rtol=1e-12, atol=1e-14).y[0, -1]

    psi_tip = brentq(base_angle, 0.0, kappa0 * length, xtol=1e-15)
    sol = solve_ivp(rhs, (length, 0.0), [psi_tip, 0.0], rtol=1e-12, atol=1e-14, dense_output=True)
    out = []
    for x in sites:
        h = quad(lambda v: np.sin(sol.sol(v)[0]), 0, x, epsabs=1e-14, limit=200)[0]
        z = quad(lambda v: -np.cos(sol.sol(v)[0]), 0, x, epsabs=1e-14, limit=200)[0]
        out.append([h, z])
    return np.asarray(out)


@pytest.mark.slow  # 19 compilations (20 s): CI's slow step
def test_pre_curved_hanging_cable_against_a_numpy_reference():
    length, n, ei, density, kappa0 = 0.5, 6, 2e-3, 0.08, 5.0
    piece = length / n
    seg = pj.Segment(
        piece,
        ei,
        1e3,
        linear_density=density,
        rest_curvature=[kappa0 * piece, 0, 0, 0, 0, 0, 0, 0],
        extensible=False,
    )
    scene = pj.Scene(
        pj.Robot([seg] * n, base_rotation=np.diag([1.0, -1.0, -1.0])),
        pj.PolynomialCurvature(3),
        loads=[pj.Gravity()],
    )
    eq = pj.solve_equilibrium(scene)
    assert eq.converged
    sites = [(i, 1.0) for i in range(n)]
    got = np.asarray(pj.markers(scene, eq.q, sites))
    reference = _hanging_cable(kappa0, ei, density * 9.81, length, piece * np.arange(1, n + 1))
    assert reference[-1, 0] > 0.1 * length  # clearly curved, not hanging straight
    np.testing.assert_allclose(got[:, [0, 2]], reference, atol=1e-8)  # measured 1.4e-10 m
    np.testing.assert_allclose(got[:, 1], 0.0, atol=1e-12)


def test_rest_curvature_length_is_checked():
    seg = pj.Segment(0.1, 0.01, 200.0, rest_curvature=[1.0, 0.0])
    with pytest.raises(ValueError, match=r"segments\[0\].rest_curvature must hold 3 numbers"):
        pj.Scene(pj.Robot([seg]), pj.PAC())


# ---------------------------------------------------------------- models per segment, inextensible
def _two_segments(extensible=True, rest=(None, None)):
    return pj.Robot(
        [
            pj.Segment(0.12, 0.015, 300.0, linear_density=0.1, rest_curvature=rest[0]),
            pj.Segment(
                0.1, 0.01, 200.0, linear_density=0.08, rest_curvature=rest[1], extensible=extensible
            ),
        ]
    )


@pytest.mark.parametrize(
    "models",
    [
        (pj.PAC(), pj.PCC()),
        slow((pj.PolynomialCurvature(1), pj.PolynomialCurvature(0))),
        slow((pj.PolynomialCurvature(1), pj.PCC())),
    ],
    ids=["PAC+PCC", "Poly1+Poly0", "Poly1+PCC"],
)
def test_mixed_models_equal_the_single_model_where_they_coincide(models):
    # A pure end moment bends the distal segment at constant curvature: there the lower-order
    # model is exact, and the robot must equal the one with the higher-order model throughout.
    loads = [pj.PointMoment(np.array([0.01, 0.02, 0.0]), 1, follower=True)]
    mixed = pj.Scene(_two_segments(), list(models), loads=loads)
    single = pj.Scene(_two_segments(), models[0], loads=loads)
    assert mixed.n_dofs == single.n_dofs - (
        models[0].dofs_per_segment() - models[1].dofs_per_segment()
    )
    a, b = pj.solve_equilibrium(mixed), pj.solve_equilibrium(single)
    assert a.converged and b.converged
    sites = [(0, 0.5), (0, 1.0), (1, 0.5), (1, 1.0)]
    np.testing.assert_allclose(
        pj.markers(mixed, a.q, sites), pj.markers(single, b.q, sites), atol=1e-12
    )


def _mixed_scene(models, tendons):
    rest = (
        [0.3, 0.1, 0.2, 0.1, 0.2, 0.3][: models[0].dofs_per_segment() - 1],
        [0.2, -0.5, 0.1, 0.1][: models[1].dofs_per_segment() - 1],
    )
    return pj.Scene(
        _two_segments(extensible=False, rest=rest),
        list(models),
        tendons=tendons,
        loads=[pj.Gravity(), pj.PointMass(0.02, 1, 0.5)],
    )


MIXED = [(pj.PAC(), pj.PCC()), (pj.PolynomialCurvature(2), pj.PolynomialCurvature(1))]


@pytest.mark.slow  # two compiled Hessians per model pair: CI's slow step
@pytest.mark.parametrize("models", MIXED, ids=["PAC+PCC", "Poly2+Poly1"])
def test_structured_hessian_with_mixed_models_is_the_autodiff_one(models):
    tendons = [
        pj.Tendon(1, angle=0.3, offset=0.01, guides=[0.25, 0.5, 0.75], mode="tension"),
        pj.Tendon(1, angle=2.0, offset=0.01, routing="channel", mode="tension"),
    ]
    scene = _mixed_scene(models, tendons)
    q = jnp.asarray(np.random.default_rng(0).normal(size=scene.n_dofs) * 0.3)
    u = jnp.array([0.5, 0.3])
    energy, grad, hess = jax.jit(lambda x: energy_derivatives(scene, x, u))(q)
    reference = jax.jit(
        lambda x: (
            scene.potential_energy(x, u),
            jax.grad(scene.potential_energy)(x, u),
            jax.hessian(scene.potential_energy)(x, u),
        )
    )(q)
    np.testing.assert_allclose(energy, reference[0], rtol=1e-13)
    np.testing.assert_allclose(grad, reference[1], atol=1e-13)
    np.testing.assert_allclose(hess, reference[2], atol=1e-12)


@pytest.mark.slow  # a batch and a single solve compiled per model pair: CI's slow step
@pytest.mark.parametrize("models", MIXED, ids=["PAC+PCC", "Poly2+Poly1"])
def test_batch_equals_single_solves_with_mixed_models(models):
    tendons = [pj.Tendon(1, angle=0.3, offset=0.01, routing="channel", mode="tension")]
    scene = _mixed_scene(models, tendons)
    controls = np.array([[0.0], [0.6], [1.5]])
    batch = pj.solve_batch(scene, controls)
    for row, u_row in enumerate(controls):
        single = pj.solve_equilibrium(scene, u_row)
        assert single.converged and bool(batch.converged[row])
        np.testing.assert_allclose(
            pj.markers(scene, batch.q[row], [(1, 1.0)]),
            pj.markers(scene, single.q, [(1, 1.0)]),
            atol=1e-9,
        )


@pytest.mark.slow  # a limit study (~15 s): CI's slow step
def test_inextensible_is_the_limit_of_axial_stiffness_and_has_one_coordinate_fewer():
    loads = [pj.Gravity(), pj.PointMass(0.05, 1)]
    rigid = pj.Scene(_two_segments(extensible=False), pj.PAC(), loads=loads)
    assert rigid.n_dofs == 7 and "dL[1]" not in rigid.coordinate_names()
    tip_rigid = pj.markers(rigid, pj.solve_equilibrium(rigid).q, [(1, 1.0)])
    gaps = []
    for k_a in (1e4, 1e5, 1e6):
        segs = list(_two_segments().segments)
        segs[1] = pj.Segment(0.1, 0.01, k_a, linear_density=0.08)
        soft = pj.Scene(pj.Robot(segs), pj.PAC(), loads=loads)
        tip = pj.markers(soft, pj.solve_equilibrium(soft).q, [(1, 1.0)])
        gaps.append(float(np.linalg.norm(tip - tip_rigid)))
    # The elongation is force / k_a: the gap falls as 1 / k_a.
    np.testing.assert_allclose(np.array(gaps[:-1]) / np.array(gaps[1:]), 10.0, rtol=1e-3)


def test_mixing_families_is_refused():
    with pytest.raises(ValueError, match="one family"):
        pj.Scene(_two_segments(), [pj.PAC(), pj.PolynomialCurvature(0)])
    with pytest.raises(ValueError, match="one family"):
        pj.Scene(_two_segments(), [pj.PolynomialCurvature(1), pj.PCC(frame="paper")])
    # PCC among polynomials: the same kinematics in Cartesian coordinates.
    scene = pj.Scene(_two_segments(), [pj.PolynomialCurvature(1), pj.PCC()])
    assert scene.segment_models[1] == pj.PolynomialCurvature(0)
    assert scene.coordinate_names()[-3:] == ("kx_0[1]", "ky_0[1]", "dL[1]")
    with pytest.raises(ValueError, match="one model per segment needs 2"):
        pj.Scene(_two_segments(), [pj.PAC()])


def test_scene_file_round_trip_of_bodies():
    text = """
[model]
type = "PAC"

[[segments]]
length = 0.2
young_modulus = 1.2e6
radius = 0.01
density = 1070.0
radius_tip = 0.006
inner_radius = 0.003
rest_curvature = [0.5, 0.1, 0.0]

[[segments]]
length = 0.05
bending_stiffness = 0.001
axial_stiffness = 100.0
extensible = false
model = "PCC"
rest_curvature = [0.3, 0.0]
"""
    scene, _, _ = scene_from_toml(text)
    assert scene.segment_models == (pj.PAC(), pj.PCC())
    assert scene.n_dofs == 4 + 2
    seg = scene.robot.segments[0]
    np.testing.assert_allclose(
        seg.axial_stiffness,
        pj.Segment.from_material(
            0.2, young_modulus=1.2e6, radius=0.01, radius_tip=0.006, inner_radius=0.003
        ).axial_stiffness,
    )
    again, _, _ = scene_from_toml(scene_to_toml(scene))
    assert again.segment_models == scene.segment_models
    for a, b in zip(
        jax.tree_util.tree_leaves(scene), jax.tree_util.tree_leaves(again), strict=True
    ):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="young_modulus"):
        scene_from_toml(text.replace("density = 1070.0", "linear_density = 0.3"))


# ------------------------------------------------------------------------------ section profiles
def test_a_profile_equal_to_a_taper_gives_the_same_robot():
    r0, r1 = 0.01, 0.006
    tapered = pj.Segment.from_material(0.2, young_modulus=E, density=RHO, radius=r0, radius_tip=r1)
    ratio = np.polynomial.polynomial.Polynomial([1.0, (r1 - r0) / r0])
    profile = pj.SectionProfile(bending=(ratio**4).coef, density=(ratio**2).coef)
    profiled = pj.Segment(
        0.2,
        tapered.bending_stiffness,
        tapered.axial_stiffness,
        tapered.torsion_stiffness,
        tapered.linear_density,
        radius=r0,
        profile=profile,
    )
    s = np.linspace(0, 1, 7)
    np.testing.assert_allclose(profiled.bending_profile(s), tapered.bending_profile(s), rtol=1e-14)
    ea = E * np.pi * r0**2
    np.testing.assert_allclose(
        pj.SectionProfile.end_load_stiffness(ea, 0.2, (ratio**2).coef),
        tapered.axial_stiffness,
        rtol=1e-13,
    )
    loads = [pj.Gravity(), pj.PointForce(np.array([0.0, 0.03, 0.0]), 0)]
    a = pj.Scene(pj.Robot([tapered]), pj.PolynomialCurvature(2), loads=loads)
    b = pj.Scene(pj.Robot([profiled]), pj.PolynomialCurvature(2), loads=loads)
    q = jnp.asarray(np.random.default_rng(1).normal(size=a.n_dofs) * 0.2)
    np.testing.assert_allclose(_energy(b, q), _energy(a, q), rtol=1e-13)


def test_profile_is_checked():
    with pytest.raises(ValueError, match=r"bending\[0\] must be 1"):
        pj.SectionProfile(bending=[2.0, 1.0])
    with pytest.raises(ValueError, match="stay > 0"):
        pj.SectionProfile(bending=[1.0, -1.5])
    with pytest.raises(ValueError, match="replaces the taper"):
        pj.Segment(
            0.1, 1.0, 1.0, radius=0.01, radius_tip=0.005, profile=pj.SectionProfile(bending=[1.0])
        )
    seg = pj.Segment(0.1, 1.0, 1.0, profile=pj.SectionProfile(bending=[1.0, 0.1, 0.1, 0.1, 0.1]))
    # Strain degree 2 and a quartic EI: the energy has degree 8, exact with 5 points.
    pj.Scene(pj.Robot([seg]), pj.PolynomialCurvature(2), quadrature_points=5)
    with pytest.raises(ValueError, match="quadrature_points must be >= 5"):
        pj.Scene(pj.Robot([seg]), pj.PolynomialCurvature(2), quadrature_points=4)


@pytest.mark.slow  # the implicit gradient and the solve compiled apart: CI's slow step
def test_gradient_through_a_solve_with_respect_to_rest_curvature():
    seg = pj.Segment(0.15, 0.004, 500.0, linear_density=0.1, rest_curvature=[0.6, 0.2, 0.0, 0.0])
    scene = pj.Scene(pj.Robot([seg, seg]), pj.PolynomialCurvature(1), loads=[pj.Gravity()])

    def tip_x(rest):
        segs = [eqx_replace(s, rest) for s in scene.robot.segments]
        sc = pj.Scene(pj.Robot(segs), scene.model, loads=scene.loads)
        return pj.markers(sc, pj.solve_equilibrium(sc, tol=1e-12).q, [(1, 1.0)])[0, 0]

    rest = jnp.asarray([0.6, 0.2, 0.0, 0.0])
    grad = jax.jit(jax.grad(tip_x))(rest)
    tip_x = jax.jit(tip_x)
    h = 1e-6
    fd = [(tip_x(rest.at[k].add(h)) - tip_x(rest.at[k].add(-h))) / (2 * h) for k in range(4)]
    np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-9)


def eqx_replace(segment, rest):
    import equinox as eqx

    return eqx.tree_at(lambda s: s.rest_curvature, segment, rest)


@pytest.mark.slow  # two more compiled programs (inverse statics, dynamics): CI's slow step
def test_inverse_statics_and_dynamics_with_mixed_models_and_an_inextensible_segment():
    segs = [
        pj.Segment(
            0.12, 0.015, 300.0, linear_density=0.1, radius=0.01, rest_curvature=[0.3, 0.0, 0.0]
        ),
        pj.Segment(0.1, 0.01, 200.0, linear_density=0.08, radius=0.008, extensible=False),
    ]
    tendons = [
        pj.Tendon(1, angle=a, offset=0.008, routing="channel", mode="tension")
        for a in (0.0, 2.1, 4.2)
    ]
    scene = pj.Scene(
        pj.Robot(segs, base_rotation=np.diag([1.0, -1.0, -1.0])),
        [pj.PAC(), pj.PCC()],
        tendons=tendons,
        loads=[pj.Gravity()],
    )
    u = np.array([0.5, 0.0, 0.1])
    eq = pj.solve_equilibrium(scene, u)
    target = np.asarray(pj.markers(scene, eq.q, [(1, 1.0)]))[0]
    inverse = pj.inverse_statics(scene, target, max_tension=5.0)
    assert inverse.successful
    reached = np.asarray(pj.markers(scene, inverse.q, [(1, 1.0)])[0])
    np.testing.assert_allclose(np.linalg.norm(reached - target), inverse.error, rtol=1e-6)
    assert inverse.error < 1e-4  # the default reached_tol
    # From rest, released under the equilibrium's tensions, the motion settles towards it.
    traj = pj.simulate(scene, (0.0, 0.05), u)
    assert traj.q.shape[-1] == scene.n_dofs == 6
    assert np.all(np.isfinite(np.asarray(traj.q)))
    np.testing.assert_array_equal(scene.coordinates(traj.q[-1])[1, [1, 3]], 0.0)  # c1, dL pinned


def test_random_starts_draw_only_the_free_coordinates():
    """find_equilibria's starts on scenes with pinned coordinates (an inextensible segment, a
    lower-order segment) have the scene's own number of coordinates."""
    from pacjax._statics.multistart import random_starts

    rigid = pj.Segment(0.3, 1e-3, 1e3, extensible=False)
    for scene in (
        pj.Scene(pj.Robot([rigid]), pj.PCC()),
        pj.Scene(pj.Robot([rigid, rigid]), [pj.PolynomialCurvature(2), pj.PCC()]),
    ):
        starts = random_starts(scene, 5, 0, 1.0, True)
        assert starts.shape == (5, scene.n_dofs)
        assert np.all(starts[0] == 0.0) and np.any(starts[1:] != 0.0)
