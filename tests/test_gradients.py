"""Derivatives of equilibria, jit / vmap of the solver, recompilation, and float32.

One scene structure for the whole module (each structure costs a compilation per transform):
two segments with polynomial curvature, hanging under gravity, a tip payload, a world-fixed
side force and two length-mode tendons (one free, one through a Bowden cable), both taut at the
equilibrium. Derivatives with respect to the controls, a tendon gain, a segment's bending
stiffness, the payload mass and the force come from ``jax.grad`` / ``jax.jacfwd`` through
``pj.solve_equilibrium`` and are compared with central finite differences of tightly converged
solves.
"""

import json
import pathlib
import subprocess
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pacjax as pj

TOL = 1e-12  # tight, so that finite differences of solves are accurate
OPTIONS = dict(tol=TOL, fallback=False)
PARAMS = ("controls", "gain", "bending_stiffness", "mass", "force")
TIP_WEIGHTS = np.array([1.0, -2.0, 0.5])
# Finite-difference steps are 1e-5 relative, or 1e-5 of these sizes for small values.
FD_FLOOR = {"controls": 0.1, "gain": 1e2, "bending_stiffness": 1e-3, "mass": 1e-2, "force": 1.0}


def _f64(x):
    return jnp.asarray(x, dtype=jnp.float64)


def _base_scene():
    segments = [
        pj.Segment(0.15, 0.02, 600.0, linear_density=0.3, radius=0.012),
        pj.Segment(0.12, 0.012, 500.0, linear_density=0.2, radius=0.010),
    ]
    robot = pj.Robot(segments, base_rotation=np.diag([1.0, -1.0, -1.0]))  # hanging
    guides = (0.0, 0.5, 1.0)
    tendons = (
        pj.Tendon(1, 0.0, 0.01, gain=2.0e3, guides=guides),
        pj.Tendon(1, 2.1, 0.008, gain=1.5e3, guides=guides, bowden=True),
    )
    loads = (
        pj.Gravity(),
        pj.PointMass(0.05, 1, 1.0),
        pj.PointForce((0.3, -0.2, 0.1), 0, 0.7),
    )
    return pj.Scene(robot, pj.PolynomialCurvature(order=1), tendons=tendons, loads=loads)


BASE = _base_scene()
BASE_PARAMS = {
    "controls": _f64([0.012, 0.006]),
    "gain": BASE.tendons[1].gain,
    "bending_stiffness": BASE.robot.segments[0].bending_stiffness,
    "mass": BASE.loads[1].mass,
    "force": BASE.loads[2].force,
}


def _build(params):
    """The base scene with ``params`` put in (values only: the structure is unchanged)."""
    scene = eqx.tree_at(
        lambda s: (
            s.tendons[1].gain,
            s.robot.segments[0].bending_stiffness,
            s.loads[1].mass,
            s.loads[2].force,
        ),
        BASE,
        (params["gain"], params["bending_stiffness"], params["mass"], params["force"]),
    )
    return scene, params["controls"]


# Compiled once for the whole module, whatever the parameter values: a second trace fails.
@eqx.filter_jit
@eqx.debug.assert_max_traces(max_traces=1)
def _solve(scene, controls, q0):
    return pj.solve_equilibrium(scene, controls, q0, **OPTIONS)


@eqx.filter_jit
@eqx.debug.assert_max_traces(max_traces=1)
def _solve_batch(scene, controls):
    return jax.vmap(lambda u: pj.solve_equilibrium(scene, u, **OPTIONS))(controls)


@eqx.filter_jit
def _tip(scene, q):
    return pj.tip_pose(scene, q)[0]


def _equilibrium_q(params, q0):
    scene, controls = _build(params)
    return pj.solve_equilibrium(scene, controls, q0, **OPTIONS).q


def _tip_loss(params, q0):
    scene, _ = _build(params)
    return _tip(scene, _equilibrium_q(params, q0)) @ TIP_WEIGHTS


# Newton steps (dt from 1e8) from a converged solve, to the round-off floor: a solve stops
# anywhere below its tolerance (the base solve at 2.4e-13, its shifted ones at 1.7e-13 and
# 5e-13), and divided by a step h of 1e-5 relative that left errors of 5e-6 to 9e-6 in the
# finite differences of the gain and the mass.
POLISH = dict(tol=1e-16, initial_dt=1e8, max_steps=3, escapes=0, fallback=False)


def _polished(scene, controls, q):
    eq = pj.solve_equilibrium(scene, controls, q, **POLISH)
    assert float(eq.residual_norm) < 1e-13, float(eq.residual_norm)
    return np.asarray(eq.q)


@pytest.fixture(scope="module")
def reference():
    """The equilibrium at the base parameters, and central differences of ``q`` and the loss."""
    # Solved through pj.solve_equilibrium, as the gradients below are: the same kinematics
    # (known load sites are knots; under an outer jit a traced site takes a quadrature that
    # agrees to ~1e-9, which moved the gain's finite difference by 1e-6 relative).
    scene, controls = _build(BASE_PARAMS)
    eq = pj.solve_equilibrium(scene, controls, scene.zeros(), **OPTIONS)
    assert bool(eq.converged) and bool(eq.stable)
    assert float(eq.residual_norm) <= TOL
    tensions = np.asarray(pj.tendon_tensions(scene, eq.q, controls))
    assert np.all(tensions > 0.1), tensions  # both taut: the derivative is smooth

    fd_q, fd_loss = {}, {}
    for name in PARAMS:
        base = np.asarray(BASE_PARAMS[name], float)
        cols_q, cols_loss = [], []
        for i in np.ndindex(base.shape):
            h = 1e-5 * max(abs(base[i]), FD_FLOOR[name])
            values = []
            for sign in (1.0, -1.0):
                shifted = base.copy()
                shifted[i] += sign * h
                params = dict(BASE_PARAMS, **{name: _f64(shifted)})
                s_scene, s_controls = _build(params)
                # Warm start: the same branch.
                s_eq = pj.solve_equilibrium(s_scene, s_controls, eq.q, **OPTIONS)
                assert bool(s_eq.converged)
                q = _polished(s_scene, s_controls, s_eq.q)
                values.append((q, float(_tip(s_scene, jnp.asarray(q)) @ TIP_WEIGHTS)))
            cols_q.append((values[0][0] - values[1][0]) / (2 * h))
            cols_loss.append((values[0][1] - values[1][1]) / (2 * h))
        fd_q[name] = np.stack(cols_q, -1).reshape(-1, *base.shape)
        fd_loss[name] = np.asarray(cols_loss).reshape(base.shape)
    return eq, fd_q, fd_loss


def _relative_error(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return np.abs(a - b).max() / np.abs(b).max()


@pytest.mark.slow  # over a minute of compilation: CI's slow step
def test_grad_of_tip_loss_matches_finite_differences(reference):
    eq, _, fd_loss = reference
    grad = jax.grad(_tip_loss)(BASE_PARAMS, BASE.zeros())
    errors = {name: _relative_error(grad[name], fd_loss[name]) for name in PARAMS}
    print("grad vs FD, relative:", errors)
    # Measured: 3e-11 (controls), 2.2e-8 (gain), 6e-10 (EI), 1.5e-10 (mass), 1e-10 (force).
    for name in PARAMS:
        assert np.all(np.abs(fd_loss[name]) > 0) or name == "force", (name, fd_loss[name])
        assert errors[name] < 1e-6, errors

    # The implicit function theorem only needs the solution, not the path to it: the gradient
    # from a start on the other side of the equilibrium is the same.
    # (Bending coordinates only: a start must not contract a segment past its stop.)
    bending = np.array(["dL" not in name for name in BASE.coordinate_names()])
    far_start = eq.q + 0.3 * jnp.sign(eq.q) * bending
    grad_far = jax.grad(_tip_loss)(BASE_PARAMS, far_start)
    for name in PARAMS:
        np.testing.assert_allclose(grad_far[name], grad[name], rtol=1e-8, atol=1e-12)


@pytest.mark.slow
def test_jacfwd_of_equilibrium_matches_finite_differences(reference):
    _, fd_q, _ = reference
    jac = jax.jacfwd(_equilibrium_q)(BASE_PARAMS, BASE.zeros())
    errors = {}
    for name in PARAMS:
        assert jac[name].shape == fd_q[name].shape
        errors[name] = _relative_error(jac[name], fd_q[name])
    print("jacfwd vs FD, relative:", errors)
    # Measured: 6e-11 (controls), 3.1e-9 (gain), 3.9e-10 (EI), 4.7e-10 (mass), 7e-11 (force),
    # with the finite differences' solves polished to the round-off floor (:data:`POLISH`);
    # from the solves as they stop below their tolerance, up to 9e-6 (the derivative of the
    # solver's last iterate, not of the exact equilibrium the implicit function theorem
    # differentiates).
    assert max(errors.values()) < 1e-6, errors


@pytest.mark.long(minutes=1.1)
@pytest.mark.slow  # over a minute of compilation: CI's slow step
def test_jit_vmap_agree_with_single_solves_and_compile_once(reference):
    eq, _, _ = reference
    controls = np.array([[0.012, 0.006], [0.0, 0.01], [0.02, 0.0], [0.005, 0.005]])
    variants = [
        BASE_PARAMS,
        # New values, same structure: neither wrapper may retrace (assert_max_traces).
        dict(
            BASE_PARAMS,
            gain=_f64(900.0),
            bending_stiffness=_f64(0.035),
            mass=_f64(0.2),
            force=_f64([-0.4, 0.0, 0.2]),
        ),
    ]
    for params in variants:
        scene, _ = _build(params)
        batch = _solve_batch(scene, jnp.asarray(controls))
        assert batch.q.shape == (len(controls), scene.n_dofs)
        assert np.all(np.asarray(batch.converged))
        for k, u in enumerate(controls):
            single = _solve(scene, jnp.asarray(u), scene.zeros())
            assert bool(single.converged)
            np.testing.assert_allclose(batch.q[k], single.q, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(batch.stable[k], single.stable)
        if params is BASE_PARAMS:
            # The reference was solved outside jit, with the load sites as knots; here they are
            # traced (another quadrature): the two discretisations agree to ~1e-9 in position,
            # 4e-7 relative in these soft coordinates.
            np.testing.assert_allclose(batch.q[0], eq.q, rtol=1e-6, atol=1e-12)


@pytest.mark.slow  # shares _solve_batch's minute of compilation with the test above
def test_non_finite_controls_inside_jit_are_reported_not_converged():
    """Inside jit the NaN cannot be rejected up front: the solve must say it failed."""
    scene, _ = _build(BASE_PARAMS)
    controls = jnp.array([[0.012, 0.006], [np.nan, 0.006], [0.0, np.inf], [0.01, 0.0]])
    batch = _solve_batch(scene, controls)
    converged = np.asarray(batch.converged)
    np.testing.assert_array_equal(converged, [True, False, False, True])
    assert not np.any(np.asarray(batch.successful)[~converged])
    assert np.all(np.isfinite(np.asarray(batch.q)[converged]))


def _run_isolated(code: str):
    """Run ``code`` in a fresh interpreter that can import this module; return its last stdout
    line as JSON. A crash of XLA (a segmentation fault) then fails one test instead of killing
    the whole test run."""
    proc = subprocess.run(
        [sys.executable, "-c", code],
        cwd=pathlib.Path(__file__).parent,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert proc.returncode == 0, (
        f"the float32 computation crashed (return code {proc.returncode}; -11 is a segmentation "
        f"fault)\n{proc.stderr[-3000:]}"
    )
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _float32_solve(tol):
    """The base scene and controls cast to float32, solved (run in a subprocess)."""
    scene, controls = _build(BASE_PARAMS)
    scene32 = pj.astype(scene, jnp.float32)
    eq = pj.solve_equilibrium(scene32, controls.astype(jnp.float32), tol=tol, fallback=False)
    tip = _tip(scene32, eq.q)
    print(
        json.dumps(
            {
                "dtype": str(eq.q.dtype),
                "converged": bool(eq.converged),
                "stable": bool(eq.stable),
                "residual_norm": float(eq.residual_norm),
                "q": np.asarray(eq.q, float).tolist(),
                "tip": np.asarray(tip, float).tolist(),
            }
        )
    )


@pytest.mark.slow
def test_float32_energy_hessian_does_not_crash():
    """What the solver differentiates twice, in float32, on a two-segment polynomial scene
    with gravity: the minimal case of a segmentation fault of XLA:CPU that killed float32
    solves at 98c7695 (3x3 products as multiply-and-sum; fixed at 2948106)."""
    out = _run_isolated(
        "import json, jax, jax.numpy as jnp, pacjax as pj\n"
        "seg = pj.Segment(0.15, 0.02, 600.0, linear_density=0.3)\n"
        "robot = pj.Robot([seg, seg])\n"
        "scene = pj.Scene(robot, pj.PolynomialCurvature(order=1), loads=(pj.Gravity(),))\n"
        "scene = pj.astype(scene, jnp.float32)\n"
        "q = jnp.full(scene.n_dofs, 0.1, jnp.float32)\n"
        "h = jax.jit(jax.hessian(lambda q: scene.potential_energy(q, None)))(q)\n"
        "print(json.dumps({'dtype': str(h.dtype), 'finite': bool(jnp.all(jnp.isfinite(h)))}))\n"
    )
    assert out == {"dtype": "float32", "finite": True}


@pytest.mark.slow
def test_float32_solve_agrees_with_float64(reference):
    eq64, _, _ = reference
    out = _run_isolated("import test_gradients as t; t._float32_solve(1e-4)")
    assert out["dtype"] == "float32"
    assert out["converged"] and out["stable"], out
    assert out["residual_norm"] <= 1e-4
    q_err = np.abs(np.asarray(out["q"]) - np.asarray(eq64.q)).max()
    tip_err = np.abs(np.asarray(out["tip"]) - np.asarray(_tip(BASE, eq64.q))).max()
    print(f"float32 (tol 1e-4): max |dq| = {q_err:.2e}, tip error = {tip_err:.2e} m")
    # Measured: |dq| = 2.8e-4, tip 4.3e-6 m; with tol 1e-5, 6.3e-7 and 6e-8 m; tol 1e-6 is
    # below float32's floor here (reported as not converged).
    assert q_err < 1e-3
    assert tip_err < 2e-5


@pytest.mark.filterwarnings("error")
def test_float32_scene_computes_in_float32_without_promotion():
    """Nothing of a float32 scene is computed in float64 and cast back (JAX warns now that such
    casts in scatters will become errors). Traced only, nothing is compiled."""
    scene32 = pj.astype(_build(BASE_PARAMS)[0], jnp.float32)
    q = jnp.zeros(scene32.n_dofs, jnp.float32)
    controls = jnp.zeros(scene32.n_tendons, jnp.float32)
    energy = jax.eval_shape(scene32.potential_energy, q, controls)
    residual = jax.eval_shape(scene32.residual, q, controls)
    tip = jax.eval_shape(lambda q: pj.tip_pose(scene32, q), q)
    assert energy.dtype == residual.dtype == tip[0].dtype == jnp.float32
