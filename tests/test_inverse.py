"""Inverse statics: commands that reach reachable targets, unreachable targets flagged, the
payload changing the answer, bounds, low tension, tracking, and bad input.

One small scene structure for the module (two segments of linear polynomial curvature, hanging,
three free tendons on the first segment and three Bowden tendons on the second, a tip mass), so
the Levenberg-Marquardt solver compiles once; tip-position targets only in the default tests.
Pose, marker and batched targets compile their own solvers and are marked slow. Every reached
target is checked independently: the returned commands are solved forward again with
``pj.solve_equilibrium`` and the tip compared with the target.
"""

import pathlib

import equinox as eqx
import numpy as np
import pytest

import pacjax as pj
from pacjax import inverse
from pacjax._inverse import inverse as inverse_module

# The whole file runs in CI's slow step:
# least-squares through equilibria: minutes of compilation on 2 cores.
pytestmark = pytest.mark.slow

ANGLES = (np.pi / 2, np.pi / 2 + 2 * np.pi / 3, np.pi / 2 + 4 * np.pi / 3)
TIP_MASS = 0.05


def _scene(tip_mass=TIP_MASS):
    segments = [pj.Segment(0.12, 0.02, 800.0, linear_density=0.3, radius=0.015)] * 2
    robot = pj.Robot(segments, base_rotation=np.diag([1.0, -1.0, -1.0]))  # hanging
    guides = (0.0, 0.25, 0.5, 0.75, 1.0)
    tendons = [
        pj.Tendon(k, a, 0.012, gain=5e3, guides=guides, bowden=k > 0)
        for k in range(2)
        for a in ANGLES
    ]
    loads = (pj.Gravity(), pj.PointMass(tip_mass, 1, 1.0))
    return pj.Scene(
        robot, pj.PolynomialCurvature(order=1), tendons=tendons, loads=loads, quadrature_points=4
    )


SCENE = _scene()
LOWER, UPPER = inverse.default_command_range(SCENE)


def _forward_tip(scene, controls):
    eq = pj.solve_equilibrium(scene, controls)
    assert bool(eq.converged) and bool(eq.stable)
    return np.asarray(pj.tip_pose(scene, eq.q)[0])


@pytest.fixture(scope="module")
def targets():
    rng = np.random.default_rng(7)
    commands = UPPER * rng.uniform(0.0, 0.45, (3, SCENE.n_tendons))
    return commands, np.array([_forward_tip(SCENE, u) for u in commands])


def test_default_command_range():
    # free tendons span segment 0 (0.12 m), Bowden tendons their own segment: half of that
    np.testing.assert_allclose(UPPER, 0.06)
    np.testing.assert_allclose(LOWER, 0.0)


@pytest.mark.long(minutes=1.7)
def test_reachable_targets_are_reached(targets):
    _, points = targets
    for point in points:
        res = pj.inverse_statics(SCENE, point)
        assert bool(res.reached), res.message
        assert res.message == "target reached"
        assert float(res.error) <= 1e-4
        np.testing.assert_allclose(res.position, point, atol=1e-4)
        # independent check: the commands, solved forward, put the tip on the target
        np.testing.assert_allclose(_forward_tip(SCENE, res.controls), point, atol=1e-4)
        assert np.all(np.asarray(res.controls) >= LOWER) and np.all(res.controls <= UPPER)
        assert int(res.iterations) >= 1 and int(res.starts) >= 1


def test_low_tension_preferred():
    """Started from antagonistic commands that reach the target exactly, the low-tension term
    moves to commands that reach it with less tension; without it the solver stays put."""
    fighting = np.full(SCENE.n_tendons, 0.02) + np.array([0.01, 0, 0, 0, 0.008, 0])
    point = _forward_tip(SCENE, fighting)
    eq = pj.solve_equilibrium(SCENE, fighting)
    tension_fighting = np.asarray(pj.tendon_tensions(SCENE, eq.q, fighting))
    # a stronger preference than the default, biasing the solution by more than reached_tol / 10:
    # the polish without it is exercised too
    res = pj.inverse_statics(SCENE, point, controls0=fighting, q0=eq.q, tension_weight=1e-4)
    assert bool(res.reached)
    # measured: 266 vs 292 N^2 (the tip height ties much of the tension to the contraction)
    assert np.sum(np.asarray(res.tensions) ** 2) < 0.95 * np.sum(tension_fighting**2)
    plain = pj.inverse_statics(SCENE, point, controls0=fighting, q0=eq.q, tension_weight=0.0)
    assert bool(plain.reached)
    np.testing.assert_allclose(plain.controls, fighting, atol=1e-6)


def test_unreachable_target_is_flagged():
    target = np.array([0.0, 0.05, -0.5])  # 0.5 m away; the robot is 0.24 m long
    res = pj.inverse_statics(SCENE, target)
    assert not bool(res.reached)
    assert bool(res.result == pj.RESULTS.target_not_reached) and "not reached" in res.message
    assert float(res.error) > 0.2
    np.testing.assert_allclose(float(res.error), np.linalg.norm(res.position - target), rtol=1e-9)
    # the closest pose: the tip points at the target (hanging, reaching sideways and down)
    assert float(res.error) < np.linalg.norm(target) - 0.2
    assert int(res.starts) == 4  # every start was tried
    np.testing.assert_allclose(_forward_tip(SCENE, res.controls), res.position, atol=1e-6)


def test_payload_changes_the_answer(targets):
    _, points = targets
    heavy = eqx.tree_at(lambda s: s.loads[1].mass, SCENE, np.asarray(0.15))
    light_res = pj.inverse_statics(SCENE, points[0])
    # load-aware re-targeting: the heavy payload starts from the light payload's answer
    heavy_res = pj.inverse_statics(heavy, points[0], controls0=light_res.controls)
    assert bool(light_res.reached) and bool(heavy_res.reached)
    assert np.max(np.abs(heavy_res.controls - light_res.controls)) > 1e-3
    # the light payload's commands miss the target with the heavy payload
    miss = np.linalg.norm(_forward_tip(heavy, light_res.controls) - points[0])
    assert miss > 1e-3
    np.testing.assert_allclose(_forward_tip(heavy, heavy_res.controls), points[0], atol=1e-4)


def test_bounds_are_respected(targets):
    commands, points = targets
    far = _forward_tip(SCENE, np.array([0.05, 0.0, 0.0, 0.0, 0.05, 0.0]))
    upper = 0.02
    res = pj.inverse_statics(SCENE, far, upper=upper, lower=0.001)
    u = np.asarray(res.controls)
    assert np.all(u <= upper) and np.all(u >= 0.001)
    assert not bool(res.reached)  # needs 50 mm of pull: out of a 20 mm motor range
    # a target reachable within the range is still reached
    inside = _forward_tip(SCENE, np.array([0.012, 0.0, 0.004, 0.0, 0.01, 0.002]))
    res = pj.inverse_statics(SCENE, inside, upper=upper, lower=0.001)
    assert bool(res.reached)
    assert np.all(np.asarray(res.controls) <= upper)


def test_tracking_is_smooth(targets):
    _, points = targets
    center = points[1]
    angle = np.linspace(0.0, np.pi / 2, 6)
    path = center + 0.01 * np.stack([np.cos(angle) - 1.0, np.sin(angle), 0.0 * angle], -1)
    tracked = pj.track(SCENE, path)
    res = tracked.waypoints
    assert res.controls.shape == (6, SCENE.n_tendons)
    assert np.all(np.asarray(res.reached))
    jumps = np.abs(np.diff(np.asarray(res.controls), axis=0))
    assert tracked.max_command_jump == pytest.approx(float(jumps.max()))
    # waypoints ~3 mm apart: the commands move by millimetres, not jump between branches
    assert tracked.max_command_jump < 0.01
    assert tracked.waypoints_per_second > 0


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(target=[0.0, 0.1]), r"target must have shape \(3,\)"),
        (dict(target=[0.0, np.nan, 0.1]), "target must be finite"),
        (dict(target=[0, 0, -0.2], upper=-1.0), "upper"),
        (dict(target=[0, 0, -0.2], lower=[0.0] * 5), "lower"),
        (dict(target=[0, 0, -0.2], n_starts=0), "n_starts"),
        (dict(target=[0, 0, -0.2], reached_tol=-1e-4), "reached_tol"),
        (dict(target=[0, 0, -0.2], max_tension=-1.0), "max_tension"),
        (dict(target=[0, 0, -0.2], max_contraction=1.5), "max_contraction"),
        (dict(target=[0, 0, -0.2], tension_weight=np.nan), "tension_weight"),
        (dict(target=[0, 0, -0.2], controls0=[0.0] * 3), "controls0"),
        (dict(target=[0, 0, -0.2], q0=np.zeros(10)), "q0 needs controls0"),
        (dict(target=[0, 0, -0.2], rotation=np.ones((3, 3))), "rotation matrix"),
        (dict(target=np.zeros((2, 3)), sites=[(0, 0.5)]), r"target must have shape \(1, 3\)"),
        (dict(target=np.zeros((1, 3)), sites=[(5, 0.5)]), "segment 5 does not exist"),
        (dict(target=[0, 0, -0.2], colour="red"), "unknown option"),
    ],
)
def test_bad_input(kwargs, match):
    target = kwargs.pop("target")
    with pytest.raises((ValueError, TypeError), match=match):
        pj.inverse_statics(SCENE, target, **kwargs)


def test_bad_scene_and_batch_input():
    with pytest.raises(TypeError, match="Scene"):
        pj.inverse_statics("scene.toml", [0, 0, -0.2])
    with pytest.raises(ValueError, match=r"\(n_targets, 3\)"):
        pj.inverse_statics_batch(SCENE, [0.0, 0.0, -0.2])
    with pytest.raises(ValueError, match=r"\(n_targets, 3\)"):
        pj.track(SCENE, np.zeros((0, 3)))
    tension_scene = pj.Scene(
        SCENE.robot, SCENE.model, tendons=[pj.Tendon(1, 0.0, 0.01, mode="tension")]
    )
    with pytest.raises(ValueError, match="tension mode"):
        pj.inverse_statics(tension_scene, [0, 0, -0.2])


def test_batch_starts_follow_the_workspace_order(monkeypatch):
    """A batched target that misses from its nearest workspace sample tries the next nearest
    (as :func:`pj.inverse_statics` does), not a random command. The Levenberg-Marquardt solve is
    replaced by a stub that reaches the target only from one sample, so nothing compiles."""
    n_samples, nt, nd = 5, SCENE.n_tendons, SCENE.n_dofs
    tips = np.array([[0.0, 0.0, -0.20 - 0.01 * i] for i in range(n_samples)])
    controls = np.linspace(0.001, 0.005, n_samples)[:, None] * np.ones(nt)
    workspace = inverse.Workspace(
        controls=controls, q=np.zeros((n_samples, nd)), tip=tips, converged=np.ones(5, bool)
    )
    target = np.array([[0.0, 0.0, -0.201]])  # nearest: sample 0, then sample 1
    seen = []

    def stub(scene, tgt, limits, u0, q0, rtol, atol, max_steps, options):
        u0 = np.asarray(u0)
        seen.append(u0[0].copy())
        hit = np.allclose(u0[0], controls[1])
        m = u0.shape[0]
        error = np.full(m, 1e-6 if hit else 1e-2)
        return inverse_module.Solve(
            controls=u0,
            q=np.asarray(q0),
            error=error,
            orientation_error=np.zeros(m),
            position=np.zeros((m, 3)),
            rotation=np.broadcast_to(np.eye(3), (m, 3, 3)),
            converged=np.ones(m, bool),
            iterations=np.full(m, 7),
        )

    monkeypatch.setattr(inverse_module, "solve_many", stub)
    out = pj.inverse_statics_batch(SCENE, target, workspace=workspace, n_starts=3)
    np.testing.assert_allclose(seen[0], controls[0])
    np.testing.assert_allclose(seen[-1], controls[1])
    assert bool(out.reached[0]) and int(out.starts[0]) == 2
    np.testing.assert_allclose(np.asarray(out.controls[0]), controls[1])


@pytest.mark.long(minutes=1.1)
def test_pose_target(targets):
    """A reachable tip pose. Levenberg-Marquardt first stops 2.7 mm short with two tendons
    slack (their Jacobian columns are zero; before the retry, all 4 starts ended there); the
    retry from those tendons pulled taut reaches the pose."""
    commands, _ = targets
    eq = pj.solve_equilibrium(SCENE, commands[2])
    position, rotation = (np.asarray(x) for x in pj.tip_pose(SCENE, eq.q))
    res = pj.inverse_statics(SCENE, position, rotation=rotation)
    assert bool(res.reached)
    assert float(res.orientation_error) <= 1e-2
    np.testing.assert_allclose(res.rotation, rotation, atol=2e-2)


@pytest.mark.long(minutes=1.0)
def test_marker_targets(targets):
    commands, _ = targets
    sites = [(0, 1.0), (1, 0.5), (1, 1.0)]
    eq = pj.solve_equilibrium(SCENE, commands[0])
    points = np.array(pj.markers(SCENE, eq.q, sites))
    points[1, 2] = np.nan  # a missing coordinate is ignored
    res = pj.inverse_statics(SCENE, points, sites=sites)
    assert bool(res.reached)
    reached = np.asarray(pj.markers(SCENE, res.q, sites))
    np.testing.assert_allclose(reached[[0, 2]], points[[0, 2]], atol=1e-4)


@pytest.mark.long(minutes=2.2)
def test_batch_matches_single_and_tension_limit(targets):
    _, points = targets
    batch = np.concatenate([points, [[0.0, 0.05, -0.5]]])
    out = pj.inverse_statics_batch(SCENE, batch, max_tension=30.0, chunk_size=4)
    assert out.controls.shape == (4, SCENE.n_tendons)
    np.testing.assert_array_equal(np.asarray(out.reached), [True, True, True, False])
    assert np.all(np.asarray(out.tensions) <= 30.0 + 0.5)  # a soft limit: hinge penalty
    for i in range(3):
        np.testing.assert_allclose(_forward_tip(SCENE, out.controls[i]), points[i], atol=1e-4)


def test_cli_inverse(tmp_path, targets):
    from click.testing import CliRunner

    from pacjax.cli.main import cli

    _, points = targets
    scene_file = (
        pathlib.Path(__file__).resolve().parent.parent
        / "experiments"
        / ("inverse_statics/two_section_arm.toml")
    )
    csv = tmp_path / "targets.csv"
    far = [0.0, 0.05, -0.5]
    csv.write_text(
        "x,y,z\n" + "\n".join(",".join(f"{v:.17g}" for v in p) for p in [*points[:2], far])
    )
    result = CliRunner().invoke(cli, ["inverse", str(scene_file), str(csv), "--out", str(tmp_path)])
    assert result.exit_code == 3, result.output  # the far target is not reached
    assert "2/3 targets reached" in result.output
    rows = np.genfromtxt(
        tmp_path / "two_section_arm_commands.csv", delimiter=",", names=True, skip_header=1
    )
    np.testing.assert_array_equal(rows["reached"], [1, 1, 0])
    for row, point in zip(rows[:2], points[:2], strict=True):
        u = np.array([row[f"u{i}"] for i in range(SCENE.n_tendons)])
        np.testing.assert_allclose(_forward_tip(SCENE, u), point, atol=1e-4)
    png = tmp_path / "two_section_arm_inverse.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y\n0.1,0.2\n")
    result = CliRunner().invoke(cli, ["inverse", str(scene_file), str(bad)])
    assert result.exit_code == 1 and "a header other than x,y,z" in result.output


@pytest.mark.parametrize("model", [pj.PAC(), pj.PolynomialCurvature(1)], ids=repr)
def test_the_implicit_function_step_uses_the_solvers_last_jacobian(model):
    """The inverse solver takes ``dF/dq`` at the equilibrium from the continuation's last
    linearisation (:func:`pacjax._statics.equilibrium.linearised_equilibrium`), with the same
    scaling: it is the forward Jacobian of the scaled residual there."""
    import jax
    import jax.numpy as jnp

    from pacjax._statics.equilibrium import linearised_equilibrium

    scene = pj.presets.stella2023(model, tip_mass=0.2)
    u = jnp.asarray(np.random.default_rng(5).uniform(0.0, 0.02, scene.n_tendons))
    eq, (jac, sigma, row) = linearised_equilibrium(scene, u, None, pj.SolverOptions())
    assert bool(eq.converged)
    expected = jax.jit(jax.jacfwd(lambda y: scene.residual(sigma * y, u) * row))(eq.q / sigma)
    np.testing.assert_allclose(jac, expected, rtol=0, atol=1e-9 * float(jnp.abs(expected).max()))
