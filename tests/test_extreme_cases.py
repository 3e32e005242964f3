"""Extreme cases (issue 6): converge, or say so explicitly; never a silent NaN.

One representative of each row of the stability suite (``experiments/stability``), on one
two-segment PCC scene STRUCTURE (gravity, a tip mass, two antagonistic tendons) whose values
change from case to case: EI, gains, payload, gravity and the base rotation are array leaves,
so every case, every hypothesis draw and every NaN input reuses one compilation per dtype.
The solve and the implicit gradient of a tip coordinate with respect to the controls are one
compiled ``jax.value_and_grad``. Float32 uses ``tol = 1e-4`` (see ``test_gradients.py``).
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from checks import scaled_residual
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import pacjax as pj
from pacjax._model.energy import STOP_BAND
from pacjax._statics.continuation import conservative_part

# The whole file runs in CI's slow step:
# extreme cases in two precisions: minutes of compilation on 2 cores.
pytestmark = pytest.mark.slow

SEG_LENGTH = 0.1
EI = 0.01  # N m^2
OFFSET = 0.01  # m
GAIN = 1e4  # N/m
TOLS = {"float64": 1e-10, "float32": 1e-4}
DTYPES = {"float64": jnp.float64, "float32": jnp.float32}
UPRIGHT = np.eye(3)
HANGING = np.diag([1.0, -1.0, -1.0])
HORIZONTAL = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
P_CR = np.pi**2 * EI / (4 * (2 * SEG_LENGTH) ** 2)  # clamped-free column, N
G = 9.81
WEIGHTS = np.array([1.0, -2.0, 0.5])


def _structure():
    seg = pj.Segment(SEG_LENGTH, EI, 1000.0, linear_density=0.1, radius=0.015)
    guides = (0.0, 0.5, 1.0)
    tendons = [pj.Tendon(1, a, OFFSET, gain=GAIN, guides=guides) for a in (0.0, np.pi)]
    loads = (pj.Gravity(), pj.PointMass(0.0, 1, 1.0))
    return pj.Scene(pj.Robot([seg, seg]), pj.PCC(), tendons=tendons, loads=loads)


STRUCTURE = _structure()


def _scene(dtype="float64", ei=EI, gain=GAIN, mass=0.0, g=G, rotation=HANGING, density=0.1):
    """The structure with these values (array leaves only: no recompilation)."""
    f = lambda x: jnp.asarray(x, DTYPES[dtype])  # noqa: E731
    return eqx.tree_at(
        lambda s: (
            [x.bending_stiffness for x in s.robot.segments]
            + [x.torsion_stiffness for x in s.robot.segments]
            + [x.linear_density for x in s.robot.segments]
            + [t.gain for t in s.tendons]
            + [s.loads[0].g, s.loads[1].mass, s.robot.base_rotation]
        ),
        pj.astype(STRUCTURE, DTYPES[dtype]),
        [f(ei)] * 2 + [f(ei / 1.5)] * 2 + [f(density)] * 2 + [f(gain)] * 2
        + [f(g), f(mass), f(rotation)],
    )  # fmt: skip


@eqx.filter_jit
def _solve_and_grad(scene, controls, tol):
    """The equilibrium and d(tip . WEIGHTS)/d(controls) in one compiled call."""

    def loss(u):
        eq = pj.solve_equilibrium(scene, u, tol=tol)
        tip = scene.frames(eq.q, np.array([1]), jnp.ones(1, u.dtype))[1][0]
        return tip @ jnp.asarray(WEIGHTS, u.dtype), eq

    (_, eq), grad = jax.value_and_grad(loss, has_aux=True)(controls)
    return eq, grad


def _solve(dtype, controls, **values):
    scene = _scene(dtype, **values)
    eq, grad = _solve_and_grad(scene, jnp.asarray(controls, DTYPES[dtype]), TOLS[dtype])
    return scene, eq, np.asarray(grad)


def _assert_explicit(eq, grad, tol):
    """Converged with a finite equilibrium and gradient, or an explicit failure flag."""
    q = np.asarray(eq.q)
    if bool(eq.converged):
        # A converged saddle is flagged, not successful.
        assert bool(eq.successful) == bool(eq.stable)
        assert eq.reason == ("converged" if bool(eq.stable) else pj.RESULTS[eq.result])
        assert float(eq.residual_norm) <= tol
        assert np.all(np.isfinite(q)), q
        assert np.isfinite(float(eq.energy))
        assert np.isfinite(float(eq.min_hessian_eigenvalue))
        assert np.all(np.isfinite(grad)), grad
    else:
        assert not bool(eq.successful) and eq.reason != "converged"
        # What is returned is the last accepted iterate (or the start), never a NaN q.
        assert np.all(np.isfinite(q)), q


def _tip(scene, q):
    return np.asarray(pj.tip_pose(scene, jnp.asarray(q))[0], float)


# Each row: values put into the structure, controls (m), and what a converged solution shows.
def _straight(scene, eq, dtype):
    np.testing.assert_allclose(
        np.asarray(eq.q)[[0, 3]], 0.0, atol=1e-12 if dtype == "float64" else 1e-6
    )


def _upright_stable_straight(scene, eq, dtype):
    _straight(scene, eq, dtype)
    assert bool(eq.stable)


def _buckled(scene, eq, dtype):
    assert bool(eq.stable)
    assert np.hypot(*_tip(scene, eq.q)[:2]) > 0.05 * 2 * SEG_LENGTH


def _tendon_holds_its_length(scene, eq, dtype):
    # A gain of 1e5 k_b / r^2: the tendon is (nearly) inextensible, tension / gain is tiny.
    tension = np.asarray(pj.tendon_tensions(scene, eq.q, jnp.asarray([0.005, 0.0], eq.q.dtype)))
    assert tension[0] > 0 and tension[0] / float(scene.tendons[0].gain) < 1e-4


def _tip_below_base(scene, eq, dtype):
    assert bool(eq.stable)
    assert _tip(scene, eq.q)[2] < 0.0


def _slack(scene, eq, dtype):
    tension = pj.tendon_tensions(scene, eq.q, jnp.asarray([-0.01, -0.01], eq.q.dtype))
    np.testing.assert_array_equal(np.asarray(tension), 0.0)
    assert _tip(scene, eq.q)[2] < 0.0  # horizontal mount, drooping under its weight


def _contracted_straight(scene, eq, dtype):
    _straight(scene, eq, dtype)
    lengths = SEG_LENGTH + np.asarray(eq.q)[[2, 5]]
    assert np.all(lengths < 0.95 * SEG_LENGTH)  # 2 cm pulled in over 0.2 m


ROWS = {
    "straight_free": (dict(g=0.0), [0.0, 0.0], _straight),
    "straight_hanging_payload": (dict(mass=0.5), [0.0, 0.0], _straight),
    "upright_half_critical": (
        dict(rotation=UPRIGHT, mass=0.5 * P_CR / G, density=0.0),
        [0.0, 0.0],
        _upright_stable_straight,
    ),
    "upright_twice_critical": (
        dict(rotation=UPRIGHT, mass=2.0 * P_CR / G, density=0.0),
        [0.0, 0.0],
        _buckled,
    ),
    "stiff_tendon_1e5": (
        dict(gain=1e5 * (EI / SEG_LENGTH) / OFFSET**2),
        [0.005, 0.0],
        _tendon_holds_its_length,
    ),
    "soft_heavy_payload": (
        dict(rotation=UPRIGHT, ei=1e-4, mass=0.2),
        [0.03, 0.0],
        _tip_below_base,
    ),
    "all_slack": (dict(rotation=HORIZONTAL), [-0.01, -0.01], _slack),
    "antagonistic_hard": (dict(gain=10 * GAIN), [0.02, 0.02], _contracted_straight),
}


@pytest.mark.parametrize("dtype", ["float64", "float32"])
@pytest.mark.parametrize("case", ROWS)
def test_extreme_case_converges_or_says_so(case, dtype):
    values, controls, check = ROWS[case]
    scene, eq, grad = _solve(dtype, controls, **values)
    print(case, dtype, bool(eq.converged), eq.reason, float(eq.residual_norm), int(eq.steps))
    _assert_explicit(eq, grad, TOLS[dtype])
    if dtype == "float64":
        assert bool(eq.converged), (eq.reason, float(eq.residual_norm))
    if bool(eq.converged):
        check(scene, eq, dtype)


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_contraction_past_the_end_of_range_is_stopped(dtype):
    """Tendons pulled by more than the robot's length: each segment rests on its end stop.

    EI 10x the default: with EI = 0.01 N m^2 the ~700 N in the two antagonistic tendons makes
    the straight state unstable (their chords between the guide rings shorten as the body
    bends), and the body folds up without an equilibrium short of self-contact.
    """
    scene, eq, grad = _solve(dtype, [0.25, 0.25], ei=10 * EI)  # more than the 0.2 m robot
    _assert_explicit(eq, grad, TOLS[dtype])
    # float32: the stop's force (~200 N here) cancels the tendons' to round-off, a scaled
    # residual of ~3e-4 against the 1e-4 tolerance: flagged, never hidden.
    if dtype == "float64":
        assert bool(eq.converged), (eq.reason, float(eq.residual_norm))
    limit = 0.9 * SEG_LENGTH  # the default contraction_limit
    contraction = -np.asarray(eq.q, float)[[2, 5]]
    assert np.all(contraction < limit)  # never past the stop
    assert np.all(contraction > limit * (1 - STOP_BAND))  # inside its contact band
    assert np.all(np.isfinite(np.asarray(grad)))


def _set_values(scene, row):
    """``update`` of :func:`pj.solve_batch`: EI, gain, payload and base rotation from a row."""
    return eqx.tree_at(
        lambda s: (
            [x.bending_stiffness for x in s.robot.segments]
            + [t.gain for t in s.tendons]
            + [s.loads[1].mass, s.robot.base_rotation]
        ),
        scene,
        [row["ei"]] * 2 + [row["gain"]] * 2 + [row["mass"], row["rotation"]],
    )


@pytest.mark.parametrize(
    "field, value",
    [
        ("ei", math.nan),
        ("gain", math.nan),
        ("mass", math.inf),
        ("rotation", np.full((3, 3), math.nan)),
    ],
    ids=["EI nan", "gain nan", "mass inf", "rotation nan"],
)
def test_non_finite_parameters_inside_jit_are_flagged(field, value):
    """Inside jit (here the vmapped batch solver: one compilation for every case) a bad value
    cannot be rejected up front: its row must say that it failed, the others must not notice.
    (Non-finite controls inside jit: ``test_gradients.py``.)"""
    rows = {
        "ei": np.full(3, EI),
        "gain": np.full(3, GAIN),
        "mass": np.full(3, 0.05),
        "rotation": np.stack([HANGING] * 3),
    }
    rows[field][1] = value
    eq = pj.solve_batch(
        _scene(), np.full((3, 2), 0.01), params=rows, update=_set_values, fallback=False
    )
    np.testing.assert_array_equal(np.asarray(eq.converged), [True, False, True])
    assert not bool(np.asarray(eq.successful)[1])
    assert "NaN or infinite" in eq.reason[1]
    assert np.all(np.isfinite(np.asarray(eq.q)))  # the failed row keeps its (finite) start
    np.testing.assert_allclose(eq.q[0], eq.q[2], rtol=1e-12)


def _log_uniform(low, high):
    return st.floats(math.log10(low), math.log10(high)).map(lambda x: 10.0**x)


@settings(
    max_examples=15,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(
    ei=_log_uniform(1e-5, 1.0),
    gain=_log_uniform(1e1, 1e8),
    mass=st.one_of(st.just(0.0), st.floats(0.0, 2.0)),
    g=st.sampled_from([0.0, G]),
    mount=st.sampled_from([UPRIGHT, HANGING, HORIZONTAL]),
    controls=st.lists(st.floats(-0.05, 0.15), min_size=2, max_size=2),
    dtype=st.sampled_from(["float64", "float32"]),
)
def test_random_extreme_scenes_never_return_silent_nan(ei, gain, mass, g, mount, controls, dtype):
    """Stiffness over five decades, gains over seven, payloads up to 2 kg, tendons slack to
    pulled by 3/4 of the robot's length: converged and finite, or an explicit flag."""
    _, eq, grad = _solve(dtype, controls, ei=ei, gain=gain, mass=mass, g=g, rotation=mount)
    _assert_explicit(eq, grad, TOLS[dtype])


@pytest.mark.long(minutes=0.9)
def test_structured_jacobian_of_a_non_conservative_scene_is_the_autodiff_one():
    """The solver's Jacobian of a scene with a follower force and a local moment: structured
    Hessian of the energy minus the forward derivative of those loads alone, equal to
    ``jax.jacfwd`` of the whole residual."""
    from pacjax._statics.problem import ScaledProblem

    loads = (
        pj.PointForce((0.5, 0.0, 2.0), segment=1, s=1.0, follower=True),
        pj.PointMoment((0.0, 0.02, 0.01), segment=0, s=0.7, follower=True),
    )
    scene = pj.presets.stella2023(pj.PAC(), n_sections=2, loads=loads, quadrature_points=4)
    assert not scene.is_conservative
    u = jnp.asarray(np.random.default_rng(3).uniform(0.0, 0.01, scene.n_tendons))
    y = jnp.asarray(np.random.default_rng(4).normal(size=scene.n_dofs)) * 0.3

    # One program for every quantity (built op by op and compiled apart they took 4 programs
    # and ~250 small compilations).
    @eqx.filter_jit
    def quantities(scene, u, y):
        problem = ScaledProblem.build(scene, u)
        return (
            problem.linearise(y),
            jax.jacfwd(problem.residual)(y),
            problem.residual(y),
            jax.value_and_grad(problem.energy)(y),
            problem.drive(y),
            problem.row / problem.sigma,
        )

    (jac, (r, (merit, _))), expected, residual, (energy, grad_e), drive, row_y = quantities(
        scene, u, y
    )
    np.testing.assert_allclose(r, residual, rtol=1e-12, atol=1e-12)
    # The merit is the energy of the conservative part; the residual is its gradient less the
    # non-conservative forces (``drive``), both scaled.
    assert float(merit) == pytest.approx(float(energy), rel=1e-12)
    np.testing.assert_allclose(r, (grad_e - drive) * row_y, rtol=1e-10, atol=1e-12)
    scale = float(jnp.max(jnp.abs(expected)))
    assert float(jnp.max(jnp.abs(jac - expected))) < 1e-10 * scale


@pytest.mark.long(minutes=1.2)
def test_follower_force_is_reached_by_load_continuation():
    # The paper's single section with a 3.41 N follower force along the body at the tip and
    # random pull-ins: from the straight start, the residual-norm merit of a non-conservative
    # solve can stall (this draw's row 1 did: 300 steps). The fallback first solves the scene
    # without the follower force, then continues with it from there (load continuation).
    force = pj.PointForce((0.0, 0.0, 3.41), segment=0, s=1.0, follower=True)
    scene = pj.presets.stella2023(pj.PCC(), loads=(force,), n_sections=1)
    commands = np.random.default_rng(1).uniform(0.0, 0.02, (2, 3))
    batch = pj.solve_batch(scene, commands)
    assert np.all(batch.converged)
    # Load continuation is not the diffrax fallback: it also runs with fallback=False, which
    # the fits and multistart solves use (a frame of the paper study's follower-force fit
    # failed at every iteration without it).
    assert np.all(pj.solve_batch(scene, commands, fallback=False).converged)
    assert bool(pj.solve_equilibrium(scene, commands[1], fallback=False).converged)
    for u, q in zip(commands, batch.q, strict=True):
        single = pj.solve_equilibrium(scene, u)
        assert bool(single.converged)
        np.testing.assert_allclose(single.q, q, atol=1e-9)
        without = pj.solve_equilibrium(conservative_part(scene), u)
        # The force does act: the equilibrium is not the one without it.
        assert np.abs(np.asarray(single.q) - np.asarray(without.q)).max() > 1e-3
        # And it is an equilibrium of the full loads (residual recomputed independently).
        assert float(scaled_residual(scene, single.q, jnp.asarray(u))) < 1e-9


def test_float32_escape_from_a_saddle_ends_at_the_stable_equilibrium():
    # Paper robot, PAC, 200 g, float32 at 1e-4: these commands (rows 2703 and 2955 of the
    # benchmark's 10,000) passed next to a saddle on the way. The residual there was below
    # 1e-4 and stayed below it after each escape of 0.05 (eigenvalue -3e-4, -7e-4), so the solve
    # stopped on the saddle, 8.4 and 14.7 mm from the float64 equilibrium. An escape now ends
    # only at a stable point.
    commands = np.array(
        [
            [0.00382077, 0.00371182, 0.01370315, 0.00210011, 0.00956628, 0.00972605,
             0.00945753, 0.00340062, 0.01977966],
            [0.00437140, 0.00848895, 0.00837125, 0.00081945, 0.01078047, 0.00894051,
             0.01455323, 0.01994017, 0.00520955],
        ]
    )  # fmt: skip
    scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
    scene32 = pj.astype(scene, jnp.float32)
    for u in commands:
        eq32 = pj.solve_equilibrium(scene32, jnp.asarray(u, jnp.float32), tol=1e-4)
        eq64 = pj.solve_equilibrium(scene, u)
        assert bool(eq32.converged) and bool(eq32.stable)
        assert bool(eq64.converged) and bool(eq64.stable)
        tip32 = pj.tip_pose(scene, jnp.asarray(eq32.q, jnp.float64))[0]
        tip64 = pj.tip_pose(scene, eq64.q)[0]
        assert float(jnp.linalg.norm(tip32 - tip64)) < 1e-4  # m


def _poly_follower(order):
    force = pj.PointForce((0.0, 0.0, 3.41), segment=2, s=1.0, follower=True)
    return pj.presets.stella2023(pj.PolynomialCurvature(order), loads=(force,))


@pytest.mark.long(minutes=1.3)
def test_order_continuation_reaches_a_row_the_straight_start_misses():
    """The paper's robot with ``PolynomialCurvature(3)`` under a 3.41 N tip follower force:
    row 16 of ``random_commands(24, seed=1)`` stalls from the straight start at a scaled
    residual of 1.4e-2 in 300 steps, and load continuation does not help. Order continuation
    (from the ``PolynomialCurvature(2)`` equilibrium, embedded) converges, with ``fallback=False``
    (no diffrax flow), in single and batch solves, to within 1 um of Poly2's tip (the model
    error of Poly2 under this load is 0.15 um against Poly5)."""
    from pacjax._statics.continuation import order_step
    from pacjax.cli.bench import random_commands

    commands = random_commands(24, seed=1)
    scene = _poly_follower(3)
    step = order_step(scene)
    assert step is not None and step.low.order == 2 and order_step(_poly_follower(1)) is None
    low = pj.solve_equilibrium(step.scene, commands[16], fallback=False)
    assert bool(low.converged)
    # the maps between the orders are exact
    q = np.asarray(low.q)
    np.testing.assert_array_equal(step.truncate(step.embed(q)), q)
    markers_low = pj.markers(step.scene, low.q)
    markers = pj.markers(scene, jnp.asarray(step.embed(q)))
    np.testing.assert_allclose(markers, markers_low, atol=1e-12)

    single = pj.solve_equilibrium(scene, commands[16], fallback=False)
    assert bool(single.converged) and bool(single.stable)
    tip_low = np.asarray(pj.tip_pose(step.scene, low.q)[0])
    assert np.linalg.norm(np.asarray(pj.tip_pose(scene, single.q)[0]) - tip_low) < 1e-6
    batch = pj.solve_batch(scene, commands[14:18], fallback=False, progress=False)
    assert bool(np.all(batch.converged))
    np.testing.assert_allclose(batch.q[2], single.q, atol=1e-8)
