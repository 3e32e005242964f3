"""Equilibria against closed-form solutions: pure end moments and tendons in tension.

References (independent of pacjax's kinematics and solver):

- a pure end moment ``M`` bends an inextensible rod into a circular arc of curvature ``M / EI``
  about the moment's axis (the internal moment is ``M`` everywhere); the arc, its frames and
  its tip angle ``M L / EI`` are written out in closed form here. Every strain model contains
  that arc, so every model must find it exactly;
- a tendon of tension ``T`` at offset ``r`` through ``n`` equally spaced guide rings of a PCC
  segment: the tendon is ``n`` straight chords of an arc of radius ``(L + dL) / c - r``, so the
  equilibrium of the reduced energy ``1/2 (EI / L) c^2 + 1/2 k_a dL^2 + T l(c, dL)`` is solved
  here by Newton on that formula. As ``n`` grows the moment arm tends to ``r`` and the curvature
  to the continuum value ``T r / EI``.

Each scene *structure* compiles once (~10-20 s); the tests vary values, not structures.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pacjax as pj

E_Z = np.array([0.0, 0.0, 1.0])

# ------------------------------------------------------------------------------ end moments
LENGTH = 0.5  # m
EI = 2.0  # N m^2
# A pure moment carries no axial force, so dL = 0 exactly whatever k_a: the arc is inextensible.
AXIAL = 1.0e4  # N/m
# Tip angles M L / EI (rad) of the in-plane cases: small, large, negative. Kept below ~3 rad: a
# dead (world-fixed) moment is not conservative in 3D, and beyond that the arc becomes an unstable
# equilibrium of the damped flow for some models (the Jacobian of the residual gets an eigenvalue
# with negative real part: PCC just past pi, PolynomialCurvature(1, twist=True) by 3 rad), which
# a flow-based solver cannot be expected to reach.
TIP_ANGLES = (0.75, 2.5, -1.2)
TILT = 0.7  # rad: moment axis (cos TILT, sin TILT, 0) in the base cross-section plane
TILTED_TIP_ANGLES = (0.75, 1.5)
N_POINTS = 41
TOL = 1e-8  # m: positions (solver tolerance 1e-10 on the scaled residual)


def _slow(model_id, model):
    return pytest.param(model, id=model_id, marks=pytest.mark.slow)


PLANAR_MODELS = [
    pytest.param(pj.PCC(), id="PCC"),
    pytest.param(pj.PAC(), id="PAC"),
    pytest.param(pj.PAC(frame="paper"), id="PAC-paper"),
]
POLYNOMIAL_MODELS = [
    pytest.param(pj.PolynomialCurvature(3, twist=True), id="poly3-twist"),
    _slow("poly1", pj.PolynomialCurvature(1)),
    _slow("poly2", pj.PolynomialCurvature(2)),
    _slow("poly3", pj.PolynomialCurvature(3)),
    _slow("poly1-twist", pj.PolynomialCurvature(1, twist=True)),
    _slow("poly2-twist", pj.PolynomialCurvature(2, twist=True)),
]


def moment_scene(model, moment):
    """One straight segment along +z, clamped at the origin, a world-fixed moment at its tip."""
    segment = pj.Segment(LENGTH, bending_stiffness=EI, axial_stiffness=AXIAL)
    return pj.Scene(pj.Robot([segment]), model, loads=(pj.PointMoment(moment, 0, 1.0),))


def rotation_about(axis, angle):
    """Rodrigues: rotation by ``angle`` (rad) about the unit ``axis``."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * k @ k


def circular_arc(axis, curvature, arc_length):
    """Exact arc of a rod clamped along +z at the origin, bent about the unit ``axis`` (in the
    xy plane) with constant ``curvature`` (1/m): positions (m) and the centre of the circle."""
    towards_centre = np.cross(axis, E_Z)  # dt/ds at s = 0 is curvature * axis x e_z
    ks = curvature * np.asarray(arc_length)
    pos = np.outer((1.0 - np.cos(ks)) / curvature, towards_centre) + np.outer(
        np.sin(ks) / curvature, E_Z
    )
    return pos, towards_centre / curvature


def check_arc(scene, eq, axis, curvature):
    """The solved backbone is the circle of radius 1 / curvature about ``axis``."""
    pos, rot = pj.backbone(scene, eq.q, N_POINTS)
    pos, rot = np.asarray(pos), np.asarray(rot)
    arc_length = np.linspace(0.0, LENGTH, N_POINTS)
    expected, centre = circular_arc(axis, curvature, arc_length)
    radius = 1.0 / abs(curvature)
    # On the circle: in its plane, at distance EI / M from its centre ...
    np.testing.assert_allclose(pos @ axis, 0.0, atol=TOL)
    np.testing.assert_allclose(np.linalg.norm(pos - centre, axis=1), radius, atol=TOL)
    # ... and at the right place on it (arc length s maps to angle curvature * s).
    np.testing.assert_allclose(pos, expected, atol=TOL)
    # The tip angle is M L / EI, and the frames turn uniformly about the moment axis.
    tangent = rot[-1][:, 2]
    tip_angle = math.atan2(tangent @ np.cross(axis, E_Z), tangent @ E_Z)
    np.testing.assert_allclose(tip_angle, curvature * LENGTH, atol=1e-9)
    for k in (N_POINTS // 2, N_POINTS - 1):
        np.testing.assert_allclose(
            rot[k], rotation_about(axis, curvature * arc_length[k]), atol=1e-8
        )


def solve(scene, **kwargs):
    eq = pj.solve_equilibrium(scene, **kwargs)
    assert bool(eq.converged), (eq.reason, float(eq.residual_norm))
    return eq


@pytest.mark.parametrize("model", PLANAR_MODELS + POLYNOMIAL_MODELS)
def test_end_moment_gives_circular_arc(model):
    axis = np.array([0.0, 1.0, 0.0])  # bends towards +x (the base frame's x axis)
    for tip_angle in TIP_ANGLES:
        moment = tip_angle * EI / LENGTH
        scene = moment_scene(model, moment * axis)
        eq = solve(scene)
        check_arc(scene, eq, axis, moment / EI)
        elongation = np.asarray(scene.coordinates(eq.q))[:, -1]
        np.testing.assert_allclose(elongation, 0.0, atol=1e-10 * LENGTH)


@pytest.mark.parametrize("model", POLYNOMIAL_MODELS)
def test_tilted_end_moment_gives_circle_in_3d(model):
    """A moment about an axis tilted in the cross-section plane: the circle lies in the plane
    normal to that axis (the bending plane is not a coordinate plane of the section)."""
    axis = np.array([math.cos(TILT), math.sin(TILT), 0.0])
    for tip_angle in TILTED_TIP_ANGLES:
        moment = tip_angle * EI / LENGTH
        scene = moment_scene(model, moment * axis)
        eq = solve(scene)
        check_arc(scene, eq, axis, moment / EI)
        if model.twist:
            # The moment has no component along the tangent anywhere on the arc: no torsion.
            n = model.order + 1
            np.testing.assert_allclose(eq.q[2 * n : 3 * n], 0.0, atol=1e-9)


def planar_reduced_equilibrium(model, moment, tilt):
    """Equilibrium ``(c0, phi)`` of a torsion-free PCC/PAC segment under a world-fixed tip moment
    ``moment (cos tilt, sin tilt, 0)``, from the arc's closed form.

    The tip frame is the rotation by ``c0`` about ``b = (-sin phi, cos phi, 0)``; ``dc0`` turns it
    about ``b`` and ``dphi`` about ``e_z - t_tip``, so the virtual work gives
    ``EI / L c0 = M sin(tilt - phi)`` and ``dE_phi / dphi = -M sin(c0) cos(phi - tilt)``, with
    ``E_phi`` the model's documented regulariser on ``phi`` (it biases the plane by
    ``~k_phi / (M sin c0)``). PAC's ``c1`` vanishes (the internal moment is uniform).
    """
    k_b = EI / LENGTH
    k_t = (EI / 1.5) / LENGTH  # the segment's default GJ / L

    def phi_force(phi):
        q = jnp.zeros(model.dofs_per_segment()).at[-2].set(phi)
        return jax.grad(lambda p: model.coordinate_energy(q.at[-2].set(p), k_t))(phi)

    def residual(x):
        c0, phi = x[0], x[1]
        return jnp.stack(
            [
                k_b * c0 - moment * jnp.sin(tilt - phi),
                phi_force(phi) + moment * jnp.sin(c0) * jnp.cos(phi - tilt),
            ]
        )

    x = jnp.array([moment / k_b, tilt - math.pi / 2])
    for _ in range(30):
        x = x - jnp.linalg.solve(jax.jacfwd(residual)(x), residual(x))
    assert float(jnp.max(jnp.abs(residual(x)))) < 1e-12
    return float(x[0]), float(x[1])


@pytest.mark.parametrize(
    # From straight the continuation does not converge (phi is undefined there) and the result
    # comes from solve_equilibrium's diffrax fallback, whose compilation takes ~1 min: slow.
    "start",
    [pytest.param("straight", marks=pytest.mark.slow), "near"],
)
@pytest.mark.parametrize("model", PLANAR_MODELS[:2])
def test_tilted_end_moment_torsion_free_planar_models(model, start):
    """PCC / PAC (torsion-free frame) turn their bending plane to the tilted moment.

    Exact up to the documented regulariser on ``phi``: the solution must be the reduced model's
    equilibrium, and within the regulariser's bias of the true circle.
    """
    axis = np.array([math.cos(TILT), math.sin(TILT), 0.0])
    for tip_angle in TILTED_TIP_ANGLES:
        moment = tip_angle * EI / LENGTH
        scene = moment_scene(model, moment * axis)
        c0, phi = planar_reduced_equilibrium(model, moment, TILT)
        # From the straight configuration (where phi is undefined), or from a start in the
        # right half-plane (the polar coordinates also have a spurious near-straight
        # equilibrium with phi = TILT, in which the moment does no work on the curvature).
        q0 = None
        if start == "near":
            q0 = np.zeros(scene.n_dofs)
            q0[0], q0[-2] = 0.5 * c0, phi + 0.4
        eq = solve(scene, q0=q0)
        q = np.asarray(scene.coordinates(eq.q))[0]
        np.testing.assert_allclose(q[0], c0, atol=1e-9)
        np.testing.assert_allclose(q[-2], phi, atol=1e-9)
        if isinstance(model, pj.PAC):
            np.testing.assert_allclose(q[1], 0.0, atol=1e-9)
        # The plane bias is small: positions within |phi - phi_exact| L of the exact circle.
        bias = abs(phi - (TILT - math.pi / 2))
        assert bias < 2e-3
        pos, _ = pj.backbone(scene, eq.q, N_POINTS)
        expected, _ = circular_arc(axis, moment / EI, np.linspace(0.0, LENGTH, N_POINTS))
        assert np.max(np.abs(np.asarray(pos) - expected)) < bias * LENGTH


def test_tilted_end_moment_paper_frame():
    """The paper's frame ``R = Rz(phi) Ry(alpha)`` rotates the whole bent segment about the base
    axis when ``phi`` changes, so a moment in the cross-section plane does no work on ``phi``,
    which stays at 0 (its real torsion stiffness): only the moment's y component bends it, in
    the xz plane. A modelling property of the paper's convention, documented by this test."""
    model = pj.PAC(frame="paper")
    axis = np.array([math.cos(TILT), math.sin(TILT), 0.0])
    for tip_angle in TILTED_TIP_ANGLES:
        moment = tip_angle * EI / LENGTH
        scene = moment_scene(model, moment * axis)
        eq = solve(scene)
        q = np.asarray(scene.coordinates(eq.q))[0]
        np.testing.assert_allclose(q, [moment * axis[1] * LENGTH / EI, 0.0, 0.0, 0.0], atol=1e-9)
        check_arc(scene, eq, np.array([0.0, 1.0, 0.0]), moment * axis[1] / EI)


# ------------------------------------------------------------------------------ tendons
T_LENGTH = 0.2  # m
T_EI = 0.01  # N m^2
T_AXIAL = 1.0e6  # N/m: dL = -T / k_a = -5e-6 m at 5 N
OFFSET = 0.01  # m
GAIN = 200.0  # N/m (kappa_P of the length-mode tendon)
CHORDS = (2, 4, 8, 16, 32)  # equally spaced guide rings: n chords from base to tip
LENGTH_MODE_CHORDS = 10  # the default 11 rings
TENSION = 5.0  # N: continuum bending angle T r L / EI = 1 rad
TOL_PHI = 1e-13  # solver tolerance that pins phi to 1e-9 rad (see check_tendon_equilibrium)


def tendon_scene(angle):
    """One PCC segment, tension-mode tendons with 2..32 chords and one length-mode tendon (all
    at the same ``angle`` and offset; the controls switch them on one at a time)."""
    tendons = [
        pj.Tendon(0, angle, OFFSET, guides=np.linspace(0.0, 1.0, n + 1), mode="tension")
        for n in CHORDS
    ]
    tendons.append(pj.Tendon(0, angle, OFFSET, gain=GAIN))
    segment = pj.Segment(T_LENGTH, bending_stiffness=T_EI, axial_stiffness=T_AXIAL)
    return pj.Scene(pj.Robot([segment]), pj.PCC(), tendons=tendons)


def chord_length(c, phi, dl, n, angle):
    """Length (m) of a tendon at ``angle`` through ``n + 1`` equally spaced rings of a PCC arc
    (bending angle ``c``, plane ``phi``): ``n`` chords of the circle of radius
    ``(L + dL) / c - r cos(phi - angle)``; the out-of-plane part of the offset is the same at
    every ring and cancels from each chord."""
    radius = (T_LENGTH + dl) / c - OFFSET * jnp.cos(phi - angle)
    return 2.0 * n * radius * jnp.sin(c / (2 * n))


def tendon_energy(c, phi, dl, params):
    """Reduced energy (J) of the PCC segment with one tension-mode tendon of ``n`` chords and
    the length-mode tendon (10 chords, rest length ``L``, commanded pull-in ``pull``)."""
    tension, n, pull, angle = params
    k_b, k_t = T_EI / T_LENGTH, (T_EI / 1.5) / T_LENGTH
    stretch = chord_length(c, phi, dl, LENGTH_MODE_CHORDS, angle) - (T_LENGTH - pull)
    return (
        0.5 * k_b * c**2
        + pj.PCC().coordinate_energy(jnp.stack([c, phi, dl]), k_t)  # the phi regulariser
        + 0.5 * T_AXIAL * dl**2
        + tension * chord_length(c, phi, dl, n, angle)
        + 0.5 * GAIN * jnp.maximum(stretch, 0.0) ** 2
    )


@jax.jit
def tendon_reduced_equilibrium(x0, params):
    """Stationary point ``(c, phi, dL)`` of :func:`tendon_energy`, by Newton from ``x0``, and
    its gradient there."""

    def grad(x):
        return jax.grad(lambda x: tendon_energy(x[0], x[1], x[2], params))(x)

    def step(_, x):
        return x - jnp.linalg.solve(jax.jacfwd(grad)(x), grad(x))

    x = jax.lax.fori_loop(0, 40, step, jnp.asarray(x0, float))
    return x, grad(x)


def check_tendon_equilibrium(eq, params):
    """``eq.q`` is the reduced model's equilibrium (from the solver's own representation: PCC's
    ``(c, phi)`` and ``(-c, phi + pi)`` are the same arc)."""
    q = np.asarray(eq.q)
    # The plane angle is stiff only through the curvature: a scaled residual tol leaves it
    # about tol / c^2 off (3e-8 rad at tol 1e-10 and c = 0.057), hence TOL_PHI in the solves.
    expected, grad = tendon_reduced_equilibrium(q, jnp.asarray(params, float))
    assert np.max(np.abs(np.asarray(grad) * [1.0, 1.0, T_LENGTH])) < 1e-13
    np.testing.assert_allclose(q[:2], expected[:2], rtol=0, atol=1e-9)
    np.testing.assert_allclose(q[2], expected[2], rtol=1e-8)


def bending_direction(scene, q):
    """Angle (rad) of the tip's displacement in the cross-section plane, and the bending angle."""
    pos, _ = pj.tip_pose(scene, q)
    c = abs(float(q[0]))
    return math.atan2(float(pos[1]), float(pos[0])), c


def angle_difference(a, b):
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


@pytest.fixture(scope="module", params=[0.0, 2.0 * math.pi / 3.0], ids=["angle0", "angle120"])
def tendon_case(request):
    return request.param, tendon_scene(request.param)


def test_tendon_tension_curvature_converges_with_guides(tendon_case):
    angle, scene = tendon_case
    continuum = TENSION * OFFSET * T_LENGTH / T_EI  # bending angle c = T r L / EI (rad)
    errors = []
    for i, n in enumerate(CHORDS):
        controls = np.zeros(scene.n_tendons)
        controls[i] = TENSION
        controls[-1] = -0.05  # the length-mode tendon slack
        eq = solve(scene, controls=controls, tol=TOL_PHI)

        # The exact equilibrium of the chord model (n chords per segment) ...
        check_tendon_equilibrium(eq, [TENSION, n, -0.05, angle])
        # ... bends it towards the tendon, the plane biased only by the phi regulariser.
        direction, c = bending_direction(scene, eq.q)
        assert angle_difference(direction, angle) < 1e-3
        tensions = np.asarray(pj.tendon_tensions(scene, eq.q, controls))
        np.testing.assert_allclose(tensions[:-1], controls[:-1], atol=1e-12)
        assert tensions[-1] == 0.0  # slack: tendons never push
        errors.append(c / continuum - 1.0)

    errors = np.asarray(errors)
    # Chords cut inside the bend: the moment arm, hence the curvature, is *larger* than T r / EI
    # (by ~ L c / (12 n^2 r)), and the excess falls as 1 / n^2 towards the continuum value.
    assert np.all(errors > 0)
    assert np.all(np.diff(errors) < 0)
    ratios = errors[:-1] / errors[1:]
    assert np.all((ratios > 3.5) & (ratios < 6.0)), ratios
    assert errors[-1] < 2e-3, errors


def test_tendon_length_mode_tension_is_gain_times_stretch(tendon_case):
    angle, scene = tendon_case
    for pull in (0.002, 0.005, 0.01):  # m
        controls = np.zeros(scene.n_tendons)
        controls[-1] = pull
        eq = solve(scene, controls=controls, tol=TOL_PHI)
        c, phi, dl = np.asarray(eq.q)

        # l_bar = l_rest - u with l_rest = L (straight tendon parallel to the axis).
        length = float(chord_length(c, phi, dl, LENGTH_MODE_CHORDS, angle))
        stretch = length - (T_LENGTH - pull)
        assert stretch > 0
        tensions = np.asarray(pj.tendon_tensions(scene, eq.q, controls))
        np.testing.assert_allclose(tensions[-1], GAIN * stretch, rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(tensions[:-1], 0.0, atol=0)

        check_tendon_equilibrium(eq, [0.0, 1.0, pull, angle])


def test_tendon_bends_the_segment_in_its_own_plane(tendon_case):
    """By symmetry a single tendon bends the segment towards its own angle, at any pull.

    PCC's torsion-free frame has a regulariser ``k_phi (1 - cos phi)`` on the plane angle
    (``k_phi = 1e-3 GJ / L``); the tendon holds the plane with a stiffness ~ ``EI / L c^2``, so
    the plane is biased by ~ ``(k_phi L / EI) sin(angle) / c^2``: negligible at c ~ 1 rad, not
    at small bends. 0.01 rad is asked for.
    """
    angle, scene = tendon_case
    for pull in (0.002, 0.01):  # m: bending angles ~0.06 and ~0.29 rad
        controls = np.zeros(scene.n_tendons)
        controls[-1] = pull
        eq = solve(scene, controls=controls, tol=TOL_PHI)
        direction, c = bending_direction(scene, eq.q)
        assert angle_difference(direction, angle) < 0.01, (pull, c, direction, angle)
