"""Tendons in continuous channels: length against an independent arc length, derivatives, the
straight limit of the ring model, the structured Hessian, solves, scene files and bad input."""

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from marks import slow

import pacjax as pj
from pacjax._model.hessian import energy_derivatives

MODELS = [pj.PCC(), pj.PAC(), pj.PolynomialCurvature(2)]


def _robot(n=2):
    segments = [
        pj.Segment(0.2, 0.02, 500.0, linear_density=0.1, radius=0.015, radius_tip=0.01),
        pj.Segment(0.1, 0.005, 300.0, linear_density=0.05, radius=0.01),
    ]
    return pj.Robot(segments[:n], base_rotation=pj.presets.MOUNTS["hanging"])


def _tendons():
    """A tapered channel through both segments, a helical one anchored mid-segment, and a
    Bowden channel in segment 1."""
    return (
        pj.Tendon(1, 0.3, 0.012, offset_end=0.004, mode="tension", routing="channel"),
        pj.Tendon(0, -1.2, 0.01, s=0.6, angle_end=0.4, mode="tension", routing="channel"),
        pj.Tendon(1, 2.0, 0.006, bowden=True, gain=300.0, routing="channel"),
    )


def _bent(scene, scale=2.5, seed=0):
    q = scale * np.random.default_rng(seed).normal(size=scene.n_dofs)
    q[scene.dofs_per_segment - 1 :: scene.dofs_per_segment] = 0.004  # elongations, m
    return jnp.asarray(q)


def _arc_length(scene, q, tendon, n=2000):
    """The tendon curve ``p + R r`` sampled densely through the public kinematics, summed as
    chords with ``n`` and ``2 n`` per segment and extrapolated (Richardson: the chords' error
    is ``~ h^2``): independent of the channel quadrature."""
    return (4.0 * _chord_sum(scene, q, tendon, 2 * n) - _chord_sum(scene, q, tendon, n)) / 3.0


@eqx.filter_jit  # once per scene structure and points (op by op it took seconds a call)
def _frames(scene, q, segment: int, s: tuple[float, ...]):
    # Known points (static) are knots of the kinematics, as they were op by op.
    return scene.frames(q, np.full(len(s), segment), np.asarray(s))


def _chord_sum(scene, q, tendon, n):
    start = tendon.entry_segment
    total = 0.0
    for k in range(start, tendon.segment + 1):
        end = tendon.s if k == tendon.segment else 1.0
        s = np.linspace(0.0, end, n + 1)
        frac = np.asarray(tendon.route_fraction(k, s))
        off_end = tendon.offset if tendon.offset_end is None else tendon.offset_end
        ang_end = tendon.angle if tendon.angle_end is None else tendon.angle_end
        rho = float(tendon.offset) + (float(off_end) - float(tendon.offset)) * frac
        alpha = float(tendon.angle) + (float(ang_end) - float(tendon.angle)) * frac
        local = np.stack([rho * np.cos(alpha), rho * np.sin(alpha), 0 * rho], -1)
        rot, pos = _frames(scene, q, k, tuple(s.tolist()))
        points = np.asarray(pos) + np.einsum("pij,pj->pi", np.asarray(rot), local)
        total += np.sum(np.linalg.norm(np.diff(points, axis=0), axis=-1))
    return total


_lengths = eqx.filter_jit(lambda scene, q: scene.tendon_lengths(q))  # once per structure


@pytest.mark.parametrize("model", [*MODELS[:2], slow(MODELS[2])], ids=lambda m: type(m).__name__)
def test_length_is_the_arc_length_of_the_tendon_curve(model):
    scene = pj.Scene(_robot(), model, _tendons())
    for q in (scene.zeros(), _bent(scene), _bent(scene, 5.0, seed=1)):
        lengths = np.asarray(_lengths(scene, q))
        reference = [_arc_length(scene, q, t) for t in scene.tendons]
        np.testing.assert_allclose(lengths, reference, rtol=1e-11)
    # The rule converges: 8 points agree with 32 to round-off on a bent pose.
    dense = pj.Scene(_robot(), model, _tendons(), quadrature_points=32)
    q = _bent(scene, 5.0, seed=1)
    np.testing.assert_allclose(_lengths(scene, q), _lengths(dense, q), rtol=1e-12)


@eqx.filter_jit  # once per scene structure (op by op: ~80 small compilations a scene)
def _lengths_and_jacobian(scene, q):
    return scene.tendon_lengths(q), jax.jacfwd(scene.tendon_lengths)(q)


def test_float32_lengths_and_derivatives_follow_float64():
    scene = pj.Scene(_robot(), pj.PAC(), _tendons())
    single = pj.astype(scene, jnp.float32)
    for q in (scene.zeros(), _bent(scene)):
        q32 = q.astype(jnp.float32)
        lengths32, jac32 = _lengths_and_jacobian(single, q32)
        lengths64, jac64 = _lengths_and_jacobian(scene, q32.astype(float))
        np.testing.assert_allclose(lengths32, lengths64, rtol=2e-6)
        np.testing.assert_allclose(jac32, jac64, atol=2e-6 * float(jnp.max(jnp.abs(jac64))))


def test_length_derivatives_against_finite_differences():
    scene = pj.Scene(_robot(), pj.PAC(), _tendons())
    q = _bent(scene)
    jac = np.asarray(_lengths_and_jacobian(scene, q)[1])
    h = 1e-6
    for j in range(scene.n_dofs):
        e = np.zeros(scene.n_dofs)
        e[j] = h
        fd = (_lengths(scene, q + e) - _lengths(scene, q - e)) / (2 * h)
        np.testing.assert_allclose(jac[:, j], fd, atol=1e-9)


def test_straight_channel_is_the_ring_model_at_rest_and_its_limit_in_a_bend():
    """At rest the chords of rings along a channel are the channel; bent, the chords cut the
    corners, and with ``n`` rings the gap closes like ``1/n^2``."""
    robot = _robot(1)

    def scene(routing, n=None):
        guides = {} if n is None else {"guides": np.linspace(0.0, 1.0, n).tolist()}
        tendon = pj.Tendon(0, 0.7, 0.012, offset_end=0.006, routing=routing, gain=1e3, **guides)
        return pj.Scene(robot, pj.PAC(), (tendon,))

    # Compiled once per scene (op by op: ~60 small compilations a scene).
    lengths = eqx.filter_jit(
        lambda scene, q: (scene.rest_tendon_lengths(), scene.tendon_lengths(q))
    )
    q = jnp.asarray([4.0, -2.0, 0.3, 0.002])
    channel_rest, channel_bent = lengths(scene("channel"), q)
    gaps = []
    for n in (11, 41, 161):
        rings_rest, rings_bent = lengths(scene("rings", n), q)
        np.testing.assert_allclose(rings_rest, channel_rest, rtol=1e-14)
        gaps.append(float(channel_bent[0] - rings_bent[0]))
    assert gaps[0] > 0
    np.testing.assert_allclose(np.array(gaps[:-1]) / np.array(gaps[1:]), 16.0, rtol=0.05)


@pytest.mark.parametrize(
    "model, dtype",
    [slow(pj.PAC(), jnp.float64), (pj.PAC(), jnp.float32)]
    + [slow(m, jnp.float64) for m in MODELS if m != pj.PAC()],
    ids=lambda x: type(x).__name__ if isinstance(x, pj.StrainModel) else jnp.dtype(x).name,
)
def test_structured_hessian_with_channels_and_rings(model, dtype):
    """The structured energy Hessian (channels, a ring tendon and a tip mass) against
    ``jax.hessian`` of the energy, straight and bent."""
    tendons = _tendons() + (pj.Tendon(1, 1.0, 0.01, gain=500.0),)
    loads = (pj.Gravity(), pj.PointMass(0.05, 1, 1.0))
    scene = pj.astype(pj.Scene(_robot(), model, tendons, loads), dtype)
    controls = jnp.asarray([2.0, 1.0, -0.003, 0.01], dtype)
    tol = 1e-10 if dtype == jnp.float64 else 2e-4
    # The structured derivatives and the autodiff ones in one program (one compilation).
    derivatives = jax.jit(
        lambda x: (
            energy_derivatives(scene, x, controls)[1:],
            jax.grad(scene.potential_energy)(x, controls),
            jax.hessian(scene.potential_energy)(x, controls),
        )
    )
    for q in (scene.zeros(dtype), _bent(scene).astype(dtype)):
        (grad, hess), ref_grad, ref_hess = derivatives(q)
        scale = float(jnp.max(jnp.abs(ref_hess)))
        np.testing.assert_allclose(grad, ref_grad, atol=tol * float(jnp.max(jnp.abs(ref_grad))))
        np.testing.assert_allclose(hess, ref_hess, atol=tol * scale)


@pytest.mark.slow  # a convergence study (~25-35 s): CI's slow step
def test_tentacle_preset_solves_and_rings_converge_to_its_channels():
    controls = jnp.asarray([[4.0, 1.0], [2.0, 6.0]])
    channel = pj.presets.tentacle()
    with warnings.catch_warnings():
        warnings.simplefilter("error", pj.SparseRingsWarning)  # channels have no rings to warn of
        eq = pj.solve_batch(channel, controls)
    assert np.all(np.asarray(eq.converged))
    tips = jax.vmap(lambda q: pj.markers(channel, q))(eq.q)
    single = pj.solve_equilibrium(channel, controls[1])
    np.testing.assert_allclose(single.q, eq.q[1], atol=1e-9)
    # Tendon 0 (towards world +y, hanging) pulls the tip towards +y.
    assert float(tips[0, -1, 1]) > 0.01 > -0.01 > float(tips[1, -1, 1])
    misses = []
    for n in (21, 81):
        rings = pj.presets.tentacle(routing="rings", n_guides=n)
        eq_r = pj.solve_batch(rings, controls)
        tips_r = jax.vmap(lambda q, r=rings: pj.markers(r, q))(eq_r.q)
        misses.append(float(jnp.max(jnp.linalg.norm(tips_r - tips, axis=-1))))
    assert misses[1] < 1e-3 < misses[0]


def test_scene_file_round_trip(tmp_path):
    scene = pj.Scene(_robot(), pj.PAC(), _tendons(), (pj.Gravity(),))
    path = tmp_path / "channels.toml"
    pj.io.save_scene(path, scene)
    text = path.read_text()
    assert 'routing = "channel"' in text and "angle_end" in text
    again, _, _ = pj.io.load_scene(path)
    assert [t.routing for t in again.tendons] == ["channel"] * 3
    q = _bent(scene)
    np.testing.assert_allclose(again.tendon_lengths(q), scene.tendon_lengths(q), rtol=1e-14)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"routing": "tube"}, "Tendon.routing"),
        ({"routing": "channel", "guides": [0.0, 1.0]}, "Tendon.guides"),
        ({"angle_end": 1.0}, "Tendon.angle_end"),
        ({"routing": "channel", "angle_end": float("nan")}, "Tendon.angle_end"),
    ],
)
def test_bad_channel_input(kwargs, message):
    with pytest.raises((ValueError, TypeError), match=message):
        pj.Tendon(0, 0.0, 0.01, gain=1.0, **kwargs)


def test_channels_need_continuous_frames():
    tendon = pj.Tendon(0, 0.0, 0.01, gain=1.0, routing="channel")
    with pytest.raises(ValueError, match="frame='paper'"):
        pj.Scene(_robot(), pj.PAC(frame="paper"), (tendon,))


@pytest.mark.slow  # the tentacle with 11 and 81 rings, 25 compilations (26 s): CI's slow step
def test_sparse_rings_warn_once_and_enough_rings_do_not(monkeypatch):
    from pacjax._statics import ringcheck

    monkeypatch.setattr(ringcheck, "_warned", set())
    controls = jnp.asarray([[7.5, 7.5]])
    sparse = pj.presets.tentacle(routing="rings", n_guides=11)
    with pytest.warns(pj.SparseRingsWarning, match=r"tendons\[0\].*routing='channel'") as caught:
        pj.solve_batch(sparse, controls)
    assert len(caught) == 2  # one per tendon
    with warnings.catch_warnings():
        warnings.simplefilter("error", pj.SparseRingsWarning)
        pj.solve_batch(sparse, 0.5 * controls)  # said once already
        pj.solve_batch(pj.presets.tentacle(routing="rings", n_guides=81), controls)
