"""Kinematics against closed forms, series and a fine integration of the frame ODE.

References, all independent of pacjax's Magnus / Gauss-Legendre kinematics:

- PCC: the circular arc in closed form (and, near the straight state, its Taylor series);
- PAC: the spec's ``R = Rz(phi) Ry(alpha) [Rz(-phi)]``, ``alpha = c0 s + c1 s^2 / 2``, with the
  position from a 64-point Gauss-Legendre rule, and the frame ODE ``R' = R [u]x`` by RK4;
- polynomial curvature (turning plane, twist): the frame ODE by RK4 with thousands of steps.

Derivatives (``jacfwd`` and ``hessian``) are checked at and near the straight configuration,
where ``sin(a)/a``-type kernels are most fragile, against the differentiated references and
against central finite differences.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from marks import slow

import pacjax as pj

LENGTH = 0.2  # m
RNG = np.random.default_rng(20231)
# Jitted once per scene structure (op-by-op dispatch of the kinematics is slow).
tip_pose = eqx.filter_jit(pj.tip_pose)
markers = eqx.filter_jit(pj.markers)
backbone = eqx.filter_jit(pj.backbone)


# ------------------------------------------------------------------------------ helpers
def _robot(n_segments=1, length=LENGTH, **kwargs):
    return pj.Robot([pj.Segment(length, 0.05, 1.0e3)] * n_segments, **kwargs)


def _rz(a, xp=np):
    c, s = xp.cos(a), xp.sin(a)
    return xp.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(a, xp=np):
    c, s = xp.cos(a), xp.sin(a)
    return xp.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _hat(v, xp=np):
    return xp.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _arc(c, phi, dl, s, frame):
    """Closed-form PCC frame at ``s``: rotation and position (m) in the segment's base frame."""
    alpha = c * s
    rot = _rz(phi) @ _ry(alpha)
    if frame == "torsion_free":
        rot = rot @ _rz(-phi)
    radial = (1.0 - math.cos(alpha)) / c
    pos = (LENGTH + dl) * np.array(
        [radial * math.cos(phi), radial * math.sin(phi), math.sin(alpha) / c]
    )
    return rot, pos


def _rk4_frames(strain, arc_length, base, n_steps):
    """Integrate ``R' = R [u(s)]x`` and ``t' = arc_length R e_z`` on [0, 1] by classical RK4.

    ``strain(s) -> (3,)`` in jax.numpy; returns ``(R, t)`` at ``s_k = k / n_steps``,
    ``k = 0..n_steps``. Differentiable (a ``scan``): the derivative reference too.
    """
    h = 1.0 / n_steps

    def rhs(s, rot):
        return rot @ _hat(strain(s), jnp), arc_length * rot[:, 2]

    def step(carry, k):
        rot, pos = carry
        s = k * h
        k1r, k1t = rhs(s, rot)
        k2r, k2t = rhs(s + h / 2, rot + h / 2 * k1r)
        k3r, k3t = rhs(s + h / 2, rot + h / 2 * k2r)
        k4r, k4t = rhs(s + h, rot + h * k3r)
        rot = rot + h / 6 * (k1r + 2 * k2r + 2 * k3r + k4r)
        pos = pos + h / 6 * (k1t + 2 * k2t + 2 * k3t + k4t)
        return (rot, pos), (rot, pos)

    start = (jnp.asarray(base), jnp.zeros(3, base.dtype))
    _, (rots, poss) = jax.lax.scan(step, start, jnp.arange(n_steps, dtype=base.dtype))
    return (
        jnp.concatenate([start[0][None], rots]),
        jnp.concatenate([start[1][None], poss]),
    )


def _poly_strain(q, order, twist):
    """Body strain of :class:`pj.PolynomialCurvature` as documented: ``u = (-k_y, k_x, tw)``."""
    n = order + 1

    def strain(s):
        powers = jnp.stack([s**j if j else jnp.ones_like(s) for j in range(n)])
        kx = q[:n] @ powers
        ky = q[n : 2 * n] @ powers
        tw = q[2 * n : 3 * n] @ powers if twist else jnp.zeros_like(kx)
        return jnp.stack([-ky, kx, tw])

    return strain


def _pac_strain(q, frame):
    """Body strain of ``Rz(phi) Ry(alpha) [Rz(-phi)]``: ``alpha'`` about ``Rz(phi) e_y`` or e_y."""

    def strain(s):
        curvature = q[0] + q[1] * s
        if frame == "paper":
            return jnp.stack([0.0 * curvature, curvature, 0.0 * curvature])
        return curvature * jnp.stack([-jnp.sin(q[2]), jnp.cos(q[2]), 0.0])

    return strain


@eqx.filter_jit
def _jit_frames(scene, q, segments, s):
    return scene.frames(q, np.asarray(segments, np.int32), np.asarray(s, float))


def _frames(scene, q, segments, s):
    rot, pos = _jit_frames(scene, jnp.asarray(q), tuple(segments), tuple(s))
    return np.asarray(rot), np.asarray(pos)


def _tip_position(scene):
    return lambda q: tip_pose(scene, q)[0]


def _derivatives(fn):
    """Jitted, batched ``(value, jacfwd, hessian)`` of ``fn`` (one compilation)."""
    return jax.jit(jax.vmap(lambda q: (fn(q), jax.jacfwd(fn)(q), jax.hessian(fn)(q))))


def _with_central_differences(batched, qs, h_jac, h_hess):
    """Value, Jacobian and Hessian at ``qs``, and their finite-difference counterparts.

    Jacobians from central differences of values, Hessians from central differences of
    Jacobians; every point in one call of ``batched`` (one compilation).
    """
    qs = np.asarray(qs)
    n, d = qs.shape
    eye = np.eye(d)
    shifts = np.concatenate([0.0 * eye[:1], h_jac * eye, -h_jac * eye, h_hess * eye, -h_hess * eye])
    points = (qs[:, None, :] + shifts[None]).reshape(-1, qs.shape[1])
    values, jacs, hessians = (
        np.asarray(x).reshape(n, len(shifts), *x.shape[1:]) for x in batched(jnp.asarray(points))
    )
    jp, jm = values[:, 1 : 1 + d], values[:, 1 + d : 1 + 2 * d]
    hp, hm = jacs[:, 1 + 2 * d : 1 + 3 * d], jacs[:, 1 + 3 * d :]
    fd_jac = np.moveaxis((jp - jm) / (2 * h_jac), 1, -1)
    fd_hess = np.moveaxis((hp - hm) / (2 * h_hess), 1, -1)
    return values[:, 0], jacs[:, 0], hessians[:, 0], fd_jac, fd_hess


def _near_straight_points(d, moderate, seed=0):
    """``q = 0``, tiny and small multiples of a random direction, and a moderate bend."""
    direction = np.random.default_rng(seed).normal(size=d)
    direction /= np.abs(direction).max()
    scales = (0.0, 1e-12, 1e-8, 1e-4, 1e-2, moderate)
    return np.stack([scale * direction for scale in scales]), scales


# ------------------------------------------------------------------------------ PCC
@pytest.mark.parametrize("frame", ["torsion_free", "paper"])
def test_pcc_matches_closed_form_circular_arc(frame):
    scene = pj.Scene(_robot(), pj.PCC(frame=frame))
    s = np.linspace(0.0, 1.0, 7)
    cases = [(2.5, -2.0, 0.0), (-1.3, 0.4, -0.03), (0.7, 3.0, 0.02), (4.0, 1.1, 0.0)]
    frames = jax.jit(lambda q: scene.frames(q, np.zeros(len(s), np.int32), s))
    worst_pos = worst_rot = 0.0
    for c, phi, dl in cases:
        rot, pos = (np.asarray(x) for x in frames(jnp.array([c, phi, dl])))
        for k, sk in enumerate(s):
            if sk == 0.0:
                ref_rot = _rz(phi) if frame == "paper" else np.eye(3)
                ref_pos = np.zeros(3)
            else:
                ref_rot, ref_pos = _arc(c, phi, dl, sk, frame)
            worst_pos = max(worst_pos, np.abs(pos[k] - ref_pos).max())
            worst_rot = max(worst_rot, np.abs(rot[k] - ref_rot).max())
    # Measured: ~1e-16 m and ~1e-15 (8 Gauss points integrate sin(c s) to round-off for c <= 4).
    assert worst_pos < 1e-13
    assert worst_rot < 1e-13


def test_pcc_any_phi_bends_in_its_plane():
    """The tip lies in the plane at angle ``phi`` whatever ``phi`` (including beyond 2 pi)."""
    scene = pj.Scene(_robot(), pj.PCC())
    tip = jax.jit(jax.vmap(_tip_position(scene)))
    phis = np.linspace(-7.0, 7.0, 29)
    qs = np.stack([np.full_like(phis, 1.2), phis, np.zeros_like(phis)], -1)
    tips = np.asarray(tip(jnp.asarray(qs)))
    radial = (1.0 - math.cos(1.2)) / 1.2 * LENGTH
    np.testing.assert_allclose(tips[:, 0], radial * np.cos(phis), atol=1e-14)
    np.testing.assert_allclose(tips[:, 1], radial * np.sin(phis), atol=1e-14)
    np.testing.assert_allclose(tips[:, 2], LENGTH * math.sin(1.2) / 1.2, atol=1e-14)


# ------------------------------------------------------------------------------ PAC
@pytest.mark.parametrize("frame", ["torsion_free", "paper"])
def test_pac_matches_fine_integration_of_frame_ode(frame):
    scene = pj.Scene(_robot(), pj.PAC(frame=frame))
    n_steps = 2000
    s = np.linspace(0.0, 1.0, 9)
    frames = jax.jit(lambda q: scene.frames(q, np.zeros(len(s), np.int32), s))
    worst_ode = worst_spec = 0.0
    for q in ([2.0, -3.0, 0.8, 0.01], [-1.0, 4.0, -2.5, -0.04], [0.3, 1e-3, 5.0, 0.0]):
        q = np.asarray(q)
        rot, pos = (np.asarray(x) for x in frames(jnp.asarray(q)))
        base = _rz(q[2]) if frame == "paper" else np.eye(3)
        ref_rots, ref_pos = _rk4_frames(
            _pac_strain(jnp.asarray(q), frame), LENGTH + q[3], base, n_steps
        )
        idx = np.rint(s * n_steps).astype(int)
        worst_ode = max(
            worst_ode,
            np.abs(pos - np.asarray(ref_pos)[idx]).max(),
            np.abs(rot - np.asarray(ref_rots)[idx]).max(),
        )
        # The spec's closed-form rotation.
        for k, sk in enumerate(s):
            spec = _rz(q[2]) @ _ry(q[0] * sk + q[1] * sk**2 / 2)
            if frame == "torsion_free":
                spec = spec @ _rz(-q[2])
            worst_spec = max(worst_spec, np.abs(rot[k] - spec).max())
    # Measured: RK4 (h = 5e-4) agrees to ~1e-15; the closed form to ~1e-15.
    assert worst_ode < 1e-11
    assert worst_spec < 1e-13


def test_pac_with_zero_c1_is_pcc():
    """``c1 = 0`` (where the paper's Fresnel form is singular) is exactly PCC."""
    pac = pj.Scene(_robot(), pj.PAC())
    pcc = pj.Scene(_robot(), pj.PCC())
    for c0, phi, dl in [(0.9, 0.3, 0.01), (1e-9, -1.0, 0.0), (-2.0, 2.0, -0.05)]:
        p_pac, r_pac = tip_pose(pac, jnp.array([c0, 0.0, phi, dl]))
        p_pcc, r_pcc = tip_pose(pcc, jnp.array([c0, phi, dl]))
        np.testing.assert_allclose(p_pac, p_pcc, atol=1e-15)
        np.testing.assert_allclose(r_pac, r_pcc, atol=1e-15)


# ------------------------------------------------------------------------------ polynomial
def _poly_reference_tip(q, order, twist, n_steps):
    rots, pos = _rk4_frames(
        _poly_strain(q, order, twist), LENGTH + q[-1], jnp.eye(3, dtype=q.dtype), n_steps
    )
    return rots[-1], pos[-1]


POLY_Q = np.array(
    # kx_0..2, ky_0..2, tw_0..2, dL: the bending plane turns and the section twists.
    [0.8, -1.5, 1.2, -0.4, 2.0, -1.0, 0.6, -1.2, 0.9, 0.015]
)


def test_polynomial_twist_matches_fine_integration_and_magnus_converges():
    model = pj.PolynomialCurvature(order=2, twist=True)
    ref_rot, ref_pos = (
        np.asarray(x) for x in _poly_reference_tip(jnp.asarray(POLY_Q), 2, True, 4000)
    )
    errors = {}
    for substeps in (8, 16):
        scene = pj.Scene(_robot(), model, rotation_substeps=substeps, quadrature_points=12)
        pos, rot = tip_pose(scene, jnp.asarray(POLY_Q))
        errors[substeps] = max(
            np.abs(np.asarray(pos) - ref_pos).max() / LENGTH,
            np.abs(np.asarray(rot) - ref_rot).max(),
        )
    # Fourth-order Magnus on the knot intervals (at most 1 / max(8, rotation_substeps) long):
    # halving them divides the error by ~16 (measured 1.1e-6 relative with 8 intervals on this
    # strongly turning and twisting strain).
    assert errors[16] < errors[8] / 12, errors
    assert errors[8] < 2e-6, errors
    # By default every segment is cut into at least 8 intervals.
    assert pj.Scene(_robot(), model).kinematics.min_intervals == 8


def test_dynamics_knot_grid_places_the_frames_as_the_statics_grid_does():
    """The dynamics' coarser knot grid (:data:`pacjax.dynamics.KNOT_GRID`, three position nodes
    on at least four intervals a segment) against the statics' default (positions to
    round-off), on the paper's robot with PAC, its curvature halving along each segment: the
    same rotations (closed form), and positions at the segments' middles and ends within 3e-8 m
    while each segment turns by up to 2 rad and 1e-6 m at 4.5 rad (measured 3.8e-11, 5.9e-9 and
    1.7e-7 m at 0.5, 2 and 4.5 rad). These grids are the coarsest the knot path takes: a
    simulation's also holds the quadrature nodes."""
    scene = pj.presets.stella2023(pj.PAC())
    coarse = scene.replace(knot_grid=pj.dynamics.KNOT_GRID)
    assert coarse.kinematics.grid == (4, 3) and scene.kinematics.grid == (8, 4)
    segments, s = np.repeat(np.arange(3), 2), np.tile([0.5, 1.0], 3)
    frames = jax.jit(lambda sc, q: sc.frames(q, segments, s))
    # (c0, c1) per segment turn it by c0 + c1 / 2 rad.
    for turn, bound in ((0.5, 2e-10), (2.0, 3e-8), (4.5, 1e-6)):
        q = jnp.tile(jnp.array([4 * turn / 3, -2 * turn / 3, 0.7, 0.002]), 3)
        (rot_f, pos_f), (rot_c, pos_c) = frames(scene, q), frames(coarse, q)
        np.testing.assert_allclose(rot_c, rot_f, rtol=0, atol=1e-15)
        assert np.abs(pos_c - pos_f).max() < bound, (turn, np.abs(pos_c - pos_f).max())
        assert np.abs(pos_c - pos_f).max() > 0


def test_polynomial_planar_matches_pac_and_is_exact_in_one_step():
    """With a fixed plane, polynomial curvature of order 1 is PAC and Magnus is exact."""
    poly = pj.Scene(_robot(), pj.PolynomialCurvature(order=1), rotation_substeps=1)
    pac = pj.Scene(_robot(), pj.PAC())
    c0, c1, phi, dl = 1.7, -2.2, 0.9, 0.01
    q_poly = jnp.array(
        [c0 * math.cos(phi), c1 * math.cos(phi), c0 * math.sin(phi), c1 * math.sin(phi), dl]
    )
    p_poly, r_poly = tip_pose(poly, q_poly)
    p_pac, r_pac = tip_pose(pac, jnp.array([c0, c1, phi, dl]))
    np.testing.assert_allclose(p_poly, p_pac, atol=1e-15)
    np.testing.assert_allclose(r_poly, r_pac, atol=1e-14)


def _halves(row, order):
    """Coefficients of ``k(s)`` on [0, 1/2] and [1/2, 1] as polynomials in ``s'`` in [0, 1],
    times 1/2 (curvature per unit ``s`` of a segment half as long)."""
    poly = np.polynomial.Polynomial(row)
    return [
        0.5 * poly(np.polynomial.Polynomial(m)).coef[: order + 1] for m in ([0.0, 0.5], [0.5, 0.5])
    ]


def test_two_polynomial_segments_chain_like_one_long_segment():
    """Two segments of length L/2 whose strains continue each other equal one of length L.

    Curvature is per unit ``s``: the half segments carry ``k(s) (L/2) / L`` reparametrised on
    their own ``s``.
    """
    order = 2
    dl = 0.012

    # Without twist and with a fixed plane, one Magnus step is exact on both sides: the chained
    # segments and the long one agree to round-off.
    planar = np.array([1.1, -0.7, 0.4])
    first, second = _halves(planar, order)
    one = pj.Scene(_robot(1, LENGTH), pj.PolynomialCurvature(order=order), rotation_substeps=1)
    two = pj.Scene(_robot(2, LENGTH / 2), pj.PolynomialCurvature(order=order), rotation_substeps=1)
    q_one = np.concatenate([planar, np.zeros(3), [dl]])
    q_two = np.concatenate([first, np.zeros(3), [dl / 2], second, np.zeros(3), [dl / 2]])
    p1, r1 = tip_pose(one, jnp.asarray(q_one))
    p2, r2 = tip_pose(two, jnp.asarray(q_two))
    np.testing.assert_allclose(p1, p2, atol=1e-15)
    np.testing.assert_allclose(r1, r2, atol=1e-14)


@pytest.mark.slow
def test_two_twisted_polynomial_segments_chain_like_one_long_segment():
    """Turning plane and twist: two half segments chain into the long one. With the same Magnus
    intervals (one segment cut into 2n, two into n each) the two are equal to round-off; with
    coarser intervals on the halves they differ by the Magnus truncation, at 4th order."""
    order = 2
    dl = 0.012
    coeffs = POLY_Q[:-1].reshape(3, order + 1)  # rows kx, ky, tw
    split = [_halves(row, order) for row in coeffs]
    q_two = np.concatenate(
        [
            np.concatenate([h[0] for h in split]),
            [dl / 2],
            np.concatenate([h[1] for h in split]),
            [dl / 2],
        ]
    )
    q_one = np.concatenate([POLY_Q[:-1], [dl]])
    model = pj.PolynomialCurvature(order=order, twist=True)

    def gap(substeps_one, substeps_two):
        one = pj.Scene(_robot(1, LENGTH), model, rotation_substeps=substeps_one)
        two = pj.Scene(_robot(2, LENGTH / 2), model, rotation_substeps=substeps_two)
        p1, r1 = tip_pose(one, jnp.asarray(q_one))
        p2, r2 = tip_pose(two, jnp.asarray(q_two))
        return max(np.abs(p1 - p2).max() / LENGTH, np.abs(r1 - r2).max())

    assert gap(16, 8) < 1e-13  # the same 16 intervals of L / 16
    coarse, fine = gap(64, 8), gap(64, 16)  # halves cut in 8 (16) against a fine reference
    assert fine < coarse / 10 and fine < 1e-7, (coarse, fine)


def test_equal_pcc_segments_chain_into_one_arc():
    """Three PCC segments with the same physical curvature and plane form one circular arc."""
    scene = pj.Scene(_robot(3, LENGTH / 3), pj.PCC())
    c, phi = 2.4, -0.6
    q = jnp.asarray(np.tile([c / 3, phi, 0.0], 3))
    pos, rot = tip_pose(scene, q)
    ref_rot, ref_pos = _arc(c, phi, 0.0, 1.0, "torsion_free")
    np.testing.assert_allclose(pos, ref_pos, atol=1e-15)
    np.testing.assert_allclose(rot, ref_rot, atol=1e-14)


# ------------------------------------------------------------------------------ frames
def test_paper_frame_twists_by_phi_even_when_straight():
    paper = pj.Scene(_robot(2), pj.PCC(frame="paper"))
    free = pj.Scene(_robot(2), pj.PCC())
    phi0 = 0.7
    q_straight = jnp.array([0.0, phi0, 0.0, 0.0, 0.0, 0.0])
    p_paper, r_paper = tip_pose(paper, q_straight)
    p_free, r_free = tip_pose(free, q_straight)
    np.testing.assert_allclose(p_paper, p_free, atol=1e-16)
    np.testing.assert_allclose(r_paper, _rz(phi0), atol=1e-15)
    np.testing.assert_allclose(r_free, np.eye(3), atol=1e-15)

    # The twist carries to the distal segment: its bending plane turns by phi0 ...
    c, phi1 = 1.3, 0.4
    p_paper, r_paper = tip_pose(paper, jnp.array([0.0, phi0, 0.0, c, phi1, 0.0]))
    p_free, r_free = tip_pose(free, jnp.array([0.0, phi0, 0.0, c, phi0 + phi1, 0.0]))
    np.testing.assert_allclose(p_paper, p_free, atol=1e-15)
    # ... and the paper's end frame differs from the torsion-free one by a twist about z.
    np.testing.assert_allclose(r_paper, r_free @ _rz(phi0 + phi1), atol=1e-14)

    # One bent segment: same backbone, end frames differ by Rz(phi) on the right.
    one_paper = pj.Scene(_robot(), pj.PCC(frame="paper"))
    one_free = pj.Scene(_robot(), pj.PCC())
    q = jnp.array([1.3, phi1, 0.0])
    p_paper, r_paper = tip_pose(one_paper, q)
    p_free, r_free = tip_pose(one_free, q)
    np.testing.assert_allclose(p_paper, p_free, atol=1e-16)
    np.testing.assert_allclose(r_paper, r_free @ _rz(phi1), atol=1e-15)


@pytest.mark.parametrize(
    "model",
    [pj.PCC(), pj.PCC(frame="paper"), pj.PAC(), pj.PolynomialCurvature(order=2, twist=True)],
    ids=["pcc", "pcc-paper", "pac", "poly2-twist"],
)
def test_rotations_are_orthonormal(model):
    scene = pj.Scene(_robot(3), model)
    qs = RNG.normal(size=(6, scene.n_dofs)) * 2.0
    qs[:, model.dofs_per_segment() - 1 :: model.dofs_per_segment()] *= 0.01  # dL in metres
    qs[0] = 0.0
    qs[1] *= 1e-6
    rots = np.asarray(jax.jit(jax.vmap(lambda q: pj.backbone(scene, q, 31)[1]))(jnp.asarray(qs)))
    gram = np.einsum("bpki,bpkj->bpij", rots, rots)
    np.testing.assert_allclose(gram, np.broadcast_to(np.eye(3), gram.shape), atol=1e-13)
    np.testing.assert_allclose(np.linalg.det(rots), 1.0, atol=1e-13)


def test_backbone_shapes_ends_and_base_pose():
    base_rot = _rz(0.4) @ _ry(1.1)
    base_pos = np.array([0.1, -0.2, 0.3])
    scene = pj.Scene(
        _robot(2, base_rotation=base_rot, base_position=base_pos), pj.PAC(frame="paper")
    )
    q = jnp.array([0.9, -0.5, 0.3, 0.01, -1.2, 0.7, 2.0, -0.02])
    pos, rot = backbone(scene, q, 21)
    assert pos.shape == (21, 3) and rot.shape == (21, 3, 3)
    pos, rot = np.asarray(pos), np.asarray(rot)
    # Base frame: the paper frame's twist by phi0 already applies at s = 0.
    np.testing.assert_allclose(pos[0], base_pos, atol=1e-16)
    np.testing.assert_allclose(rot[0], base_rot @ _rz(0.3), atol=1e-15)
    tip_pos, tip_rot = tip_pose(scene, q)
    np.testing.assert_allclose(pos[-1], tip_pos, atol=1e-16)
    np.testing.assert_allclose(rot[-1], tip_rot, atol=1e-16)
    # Evenly spaced in segment + s: point 10 is the joint.
    j_rot, j_pos = _frames(scene, q, [0], [1.0])
    np.testing.assert_allclose(pos[10], j_pos[0], atol=1e-16)
    # World frame = base pose applied to the robot in its own base frame.
    local = pj.Scene(_robot(2), pj.PAC(frame="paper"))
    l_pos, l_rot = (np.asarray(x) for x in backbone(local, q, 21))
    np.testing.assert_allclose(pos, base_pos + l_pos @ base_rot.T, atol=1e-15)
    np.testing.assert_allclose(rot, base_rot @ l_rot, atol=1e-15)
    # Consecutive points are one arc-length step apart at most (chords of the backbone).
    steps = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    spacing = np.array([LENGTH + 0.01] * 10 + [LENGTH - 0.02] * 10) / 10
    assert np.all(steps <= spacing + 1e-15) and np.all(steps > 0.9 * spacing)


def test_markers_with_local_offsets():
    scene = pj.Scene(
        _robot(2), pj.PolynomialCurvature(order=1), markers=((0, 0.5), (1, 1.0, (0.0, 0.02, 0.0)))
    )
    q = jnp.array([0.5, -0.3, 0.2, 0.8, 0.01, -0.9, 0.1, 0.4, 0.3, -0.02])
    sites = ((0, 0.0), (0, 0.25, (0.01, 0.0, 0.0)), (1, 0.6, (0.003, -0.004, 0.05)), (1, 1.0))
    out = np.asarray(markers(scene, q, sites))
    assert out.shape == (4, 3)
    rot, pos = _frames(scene, q, [s[0] for s in sites], [s[1] for s in sites])
    for k, site in enumerate(sites):
        offset = np.asarray(site[2]) if len(site) == 3 else np.zeros(3)
        np.testing.assert_allclose(out[k], pos[k] + rot[k] @ offset, atol=1e-16)
    np.testing.assert_allclose(out[0], 0.0, atol=1e-16)
    # An offset along the local x axis sits at that distance from the backbone.
    np.testing.assert_allclose(np.linalg.norm(out[1] - pos[1]), 0.01, rtol=1e-13)
    # The scene's own markers are the default sites.
    default = np.asarray(markers(scene, q))
    rot, pos = _frames(scene, q, [0, 1], [0.5, 1.0])
    np.testing.assert_allclose(default[0], pos[0], atol=1e-16)
    np.testing.assert_allclose(default[1], pos[1] + rot[1] @ [0.0, 0.02, 0.0], atol=1e-16)


# ------------------------------------------------------------------------------ derivatives
def _pcc_series_tip(q):
    """Taylor series of the PCC tip (exact to round-off for |c| <= 0.1)."""
    c, phi, dl = q
    c2 = c * c
    radial = c * (1 / 2 - c2 * (1 / 24 - c2 * (1 / 720 - c2 * (1 / 40320 - c2 / 3628800))))
    axial = 1 - c2 * (1 / 6 - c2 * (1 / 120 - c2 * (1 / 5040 - c2 / 362880)))
    return (LENGTH + dl) * jnp.stack([radial * jnp.cos(phi), radial * jnp.sin(phi), axial])


def _pcc_closed_tip(q):
    c, phi, dl = q
    radial = (1 - jnp.cos(c)) / c
    return (LENGTH + dl) * jnp.stack([radial * jnp.cos(phi), radial * jnp.sin(phi), jnp.sin(c) / c])


_GL64 = np.polynomial.legendre.leggauss(64)


def _pac_reference_tip(q):
    """Spec: ``(L + dL) Rz(phi) int_0^1 (sin alpha, 0, cos alpha) dv``, 64 Gauss points."""
    c0, c1, phi, dl = q
    v = 0.5 * (jnp.asarray(_GL64[0]) + 1.0)
    w = 0.5 * jnp.asarray(_GL64[1])
    alpha = c0 * v + c1 * v**2 / 2
    in_plane = jnp.stack([w @ jnp.sin(alpha), 0.0 * c0, w @ jnp.cos(alpha)])
    return (LENGTH + dl) * (_rz(phi, jnp) @ in_plane)


def _pcc_reference_tip(qs):
    """Series near straight, closed form elsewhere: (values, jacobians, hessians)."""
    small = np.abs(qs[:, 0]) <= 0.1
    out = [np.zeros((len(qs), 3) + (3,) * k) for k in range(3)]
    for mask, fn in ((small, _pcc_series_tip), (~small, _pcc_closed_tip)):
        if mask.any():
            for k, x in enumerate(_derivatives(fn)(jnp.asarray(qs[mask]))):
                out[k][mask] = np.asarray(x)
    return out


def _batched_reference(fn):
    return lambda qs: [np.asarray(x) for x in _derivatives(fn)(jnp.asarray(qs))]


@pytest.mark.slow
def test_twist_bend_hessian_at_straight_converges_with_magnus_substeps():
    """The one inexact second derivative at q = 0 (bend-twist commutator) is Magnus truncation."""
    reference = DERIVATIVE_CASES["poly2-twist"][1]
    q = np.zeros((1, 10))
    ref_hess = reference(q)[2][0]
    errors = []
    # At least 8 Magnus intervals per segment (KinematicsConfig.min_intervals): 8 and 16.
    for substeps in (8, 16):
        model = pj.PolynomialCurvature(order=2, twist=True)
        scene = pj.Scene(_robot(), model, rotation_substeps=substeps)
        hess = np.asarray(_derivatives(_tip_position(scene))(jnp.asarray(q))[2][0])
        errors.append(np.abs(hess - ref_hess).max())
    # Measured (knot kinematics): 6.2e-8 with 8 intervals, 4.1e-9 with 16 (ratio 15 ~ 2^4).
    assert errors[1] < errors[0] / 12, errors
    assert errors[1] < 1e-8, errors


def _check_taylor_at_straight(name, jac, hess):
    """Hand-derived series of the tip at q = 0 (phi = 0):

    PCC ``x = L c / 2 - ...``, ``z = L - L c^2 / 6``; PAC ``x = L (c0 / 2 + c1 / 6)``,
    ``z = L - L (c0^2 / 3 + c0 c1 / 4 + c1^2 / 20) / 2``; polynomial
    ``dx/dkx_j = L / ((j + 1)(j + 2))``, ``d2z/dkx_i dkx_j = -L / ((i + 1)(j + 1)(i + j + 3))``.
    """
    if name == "pcc":
        np.testing.assert_allclose(jac, [[LENGTH / 2, 0, 0], [0, 0, 0], [0, 0, 1]], atol=1e-16)
        np.testing.assert_allclose(hess[2, 0, 0], -LENGTH / 3, rtol=1e-14)
        np.testing.assert_allclose(hess[1, 0, 1], LENGTH / 2, rtol=1e-14)  # d2y / dc dphi
        np.testing.assert_allclose(hess[0, 0, 2], 0.5, rtol=1e-14)  # d2x / dc ddL
    elif name.startswith("pac"):
        np.testing.assert_allclose(jac[0], [LENGTH / 2, LENGTH / 6, 0, 0], atol=1e-16)
        expected = -LENGTH * np.array([[1 / 3, 1 / 8], [1 / 8, 1 / 20]])
        np.testing.assert_allclose(hess[2, :2, :2], expected, rtol=1e-14)
    else:
        n = 3  # order 2
        j = np.arange(n)
        np.testing.assert_allclose(jac[0, :n], LENGTH / ((j + 1) * (j + 2)), rtol=1e-14)
        np.testing.assert_allclose(jac[1, n : 2 * n], LENGTH / ((j + 1) * (j + 2)), rtol=1e-14)
        np.testing.assert_allclose(jac[:, 2 * n : 3 * n], 0.0, atol=1e-16)  # twist alone
        i, k = np.meshgrid(j, j, indexing="ij")
        expected = -LENGTH / ((i + 1) * (k + 1) * (i + k + 3))
        np.testing.assert_allclose(hess[2, :n, :n], expected, rtol=1e-13)
        np.testing.assert_allclose(hess[2, n : 2 * n, n : 2 * n], expected, rtol=1e-13)


DERIVATIVE_CASES = {
    "pcc": (pj.PCC(), _pcc_reference_tip),
    "pac": (pj.PAC(), _batched_reference(_pac_reference_tip)),
    "pac-paper": (pj.PAC(frame="paper"), _batched_reference(_pac_reference_tip)),
    # RK4 with 1000 steps of the frame ODE.
    "poly2-twist": (
        pj.PolynomialCurvature(order=2, twist=True),
        _batched_reference(lambda q: _poly_reference_tip(q, 2, True, 1000)[1]),
    ),
}


@pytest.mark.parametrize(
    "name",
    [
        "pcc",
        "pac",
        pytest.param("pac-paper", marks=pytest.mark.slow),
        pytest.param("poly2-twist", marks=pytest.mark.slow),
    ],
)
def test_tip_derivatives_at_and_near_straight(name):
    model, reference = DERIVATIVE_CASES[name]
    scene = pj.Scene(_robot(), model)
    lib = _derivatives(_tip_position(scene))
    d = scene.n_dofs
    qs, scales = _near_straight_points(d, 0.7)
    # Straddle the switch of the rotation kernels to their series (|Magnus step|^2 = 1e-3).
    edge = scene.kinematics.rotation_substeps * math.sqrt(1e-3)
    at_edge = np.zeros((2, d))
    at_edge[:, 0] = edge * np.array([1 - 1e-9, 1 + 1e-9])
    qs = np.concatenate([qs, at_edge])
    qs[:, -1] *= 0.02  # dL in metres
    value, jac, hess, fd_jac, fd_hess = _with_central_differences(lib, qs, 1e-6, 1e-5)
    assert np.all(np.isfinite(value)) and np.all(np.isfinite(jac)) and np.all(np.isfinite(hess))

    _check_taylor_at_straight(name, jac[0], hess[0])

    # Against the independent reference, differentiated by JAX.
    ref_value, ref_jac, ref_hess = reference(qs)
    errors = np.array(
        [
            [
                np.abs(value[k] - ref_value[k]).max() / LENGTH,
                np.abs(jac[k] - ref_jac[k]).max(),
                np.abs(hess[k] - ref_hess[k]).max(),
            ]
            for k in range(len(qs))
        ]
    )
    moderate = len(scales) - 1
    near = np.delete(errors, moderate, axis=0)
    if name == "poly2-twist":
        # Measured. The fourth-order Magnus step with the default 4 sub-steps does not integrate
        # the commutator of a quadratic bend with a quadratic twist exactly: d2y / dkx_2 dtw_1
        # at q = 0 is 2.22258e-3 m instead of 2.22222e-3 m (see the slow test below: it
        # converges at 4th order). Near-straight values: 2e-14 (the reference's round-off), 5e-11
        # at a strain of 1e-2;
        # gradients 6e-9; Hessians 3.7e-7 m. At the moderate bend: 4e-7, 4.4e-7, 1.7e-6.
        near_tol, far_tol = [1e-10, 2e-8, 5e-7], [2e-6, 2e-6, 5e-6]
    else:
        # Measured: round-off (<= 2.5e-16) everywhere.
        near_tol = far_tol = [1e-15, 1e-14, 1e-13]
    assert np.all(near < near_tol), errors
    assert np.all(errors[moderate] < far_tol), errors

    # No jump where the kernels switch to their series.
    np.testing.assert_allclose(jac[-2], jac[-1], atol=1e-13)
    np.testing.assert_allclose(hess[-2], hess[-1], atol=1e-12)

    # Against central finite differences of pacjax itself.
    np.testing.assert_allclose(jac, fd_jac, atol=1e-9)
    np.testing.assert_allclose(hess, fd_hess, atol=1e-8)


# ------------------------------------------------------------------------------ energy
def _loaded_scene(model):
    """Two segments with gravity, a payload, a world force and tendons of both modes."""
    robot = pj.Robot(
        [pj.Segment(0.15, 0.02, 800.0, linear_density=0.4, radius=0.01)] * 2,
        base_rotation=np.diag([1.0, -1.0, -1.0]),
    )
    tendons = (
        pj.Tendon(0, 0.3, 0.01, mode="tension", guides=(0.0, 0.5, 1.0)),
        pj.Tendon(1, 2.0, 0.012, offset_end=0.008, gain=3e3, guides=(0.0, 0.5, 1.0)),
        pj.Tendon(1, -2.0, 0.01, s=0.7, bowden=True, mode="tension", guides=(0.0, 0.5)),
    )
    loads = (
        pj.Gravity(),
        pj.PointMass(0.05, 1, 1.0),
        pj.PointForce((0.2, -0.1, 0.05), 0, 0.6),
    )
    # The length-mode tendon is pulled so that it is taut near the straight state.
    return pj.Scene(robot, model, tendons, loads), jnp.array([1.5, 0.004, 0.8])


ENERGY_MODELS = {
    "pcc": pj.PCC(),
    "pac": pj.PAC(),
    "poly1-twist": pj.PolynomialCurvature(order=1, twist=True),
}


@pytest.mark.parametrize(
    "name",
    [
        "pac",
        pytest.param("pcc", marks=pytest.mark.slow),
        pytest.param("poly1-twist", marks=pytest.mark.slow),
    ],
)
def test_potential_energy_derivatives_at_and_near_straight(name):
    scene, controls = _loaded_scene(ENERGY_MODELS[name])
    batched = _derivatives(lambda q: scene.potential_energy(q, controls))
    qs, _ = _near_straight_points(scene.n_dofs, 0.5)
    d = scene.dofs_per_segment
    qs[:, d - 1 :: d] *= 0.02
    value, grad, hess, fd_grad, fd_hess = _with_central_differences(batched, qs, 1e-6, 1e-6)
    assert np.all(np.isfinite(value)) and np.all(np.isfinite(grad)) and np.all(np.isfinite(hess))
    np.testing.assert_allclose(hess, np.swapaxes(hess, 1, 2), atol=1e-12 * np.abs(hess).max())
    scale = np.abs(hess).max()
    # FD error ~ h^2 V''' + eps V / h: measured ~1e-9 relative.
    np.testing.assert_allclose(grad, fd_grad, atol=1e-7 * scale)
    np.testing.assert_allclose(hess, fd_hess, atol=1e-7 * scale)
    # The Hessian is continuous through q = 0 (no spurious term at exactly zero).
    np.testing.assert_allclose(hess[0], hess[1], atol=1e-9 * scale)


def test_elastic_hessian_at_straight_is_the_hankel_form():
    seg = pj.Segment(0.15, 0.02, 800.0, torsion_stiffness=0.01)
    robot = pj.Robot([seg])
    k_b, k_t, k_a = 0.02 / 0.15, 0.01 / 0.15, 800.0

    hess = np.asarray(jax.jit(jax.hessian(pj.Scene(robot, pj.PAC()).elastic_energy))(jnp.zeros(4)))
    expected = np.zeros((4, 4))
    expected[:2, :2] = k_b * np.array([[1.0, 0.5], [0.5, 1 / 3]])
    # Torsion-free frame: phi only orients the bending plane; its stiffness is a documented
    # regulariser (a small factor on GJ / L).
    factor = pj.PAC().phi_stiffness_factor()
    assert 0 < factor <= 1e-3
    expected[2, 2] = factor * k_t
    expected[3, 3] = k_a
    np.testing.assert_allclose(hess, expected, rtol=1e-13, atol=1e-16)

    hess = np.asarray(
        jax.jit(jax.hessian(pj.Scene(robot, pj.PAC(frame="paper")).elastic_energy))(jnp.zeros(4))
    )
    expected[2, 2] = k_t  # the paper's k_phi = GJ / L
    np.testing.assert_allclose(hess, expected, rtol=1e-13, atol=1e-16)

    order = 2
    scene = pj.Scene(robot, pj.PolynomialCurvature(order=order, twist=True))
    hess = np.asarray(jax.jit(jax.hessian(scene.elastic_energy))(jnp.zeros(scene.n_dofs)))
    i, j = np.meshgrid(np.arange(1, order + 2), np.arange(1, order + 2), indexing="ij")
    hankel = 1.0 / (i + j - 1)
    expected = np.zeros((scene.n_dofs, scene.n_dofs))
    n = order + 1
    expected[:n, :n] = expected[n : 2 * n, n : 2 * n] = k_b * hankel
    expected[2 * n : 3 * n, 2 * n : 3 * n] = k_t * hankel
    expected[-1, -1] = k_a
    np.testing.assert_allclose(hess, expected, rtol=1e-13, atol=1e-16)


@pytest.mark.parametrize(
    "model",
    [pj.PAC()] + [slow(m) for m in (pj.PCC(), pj.PAC(frame="paper"), pj.PCC(frame="paper"))],
    ids=repr,
)
def test_closed_form_plane_frames_match_the_magnus_path(model, monkeypatch):
    """PCC and PAC bend in one plane per segment, and the kinematics takes their closed-form
    frames; the general Magnus path (exact for a fixed axis) must give the same energy,
    gradient, Hessian and frames on the paper's robot, far from straight."""
    from pacjax._model.hessian import energy_derivatives

    scene = pj.presets.stella2023(model, tip_mass=0.2)
    q = jnp.asarray(np.random.default_rng(3).uniform(-1.0, 1.0, scene.n_dofs))
    d = scene.dofs_per_segment
    q = q.at[d - 1 :: d].multiply(0.005)
    controls = jnp.asarray(np.random.default_rng(4).uniform(0.0, 0.02, scene.n_tendons))
    segs, ss = np.array([0, 1, 2, 2]), jnp.array([0.3, 0.7, 0.55, 1.0])

    def evaluate():
        return jax.jit(
            lambda q: (energy_derivatives(scene, q, controls), scene.frames(q, segs, ss))
        )(q)

    closed = evaluate()
    monkeypatch.setattr(type(model), "plane_frames", lambda self, q, s: None)
    magnus = evaluate()
    for a, b in zip(jax.tree.leaves(closed), jax.tree.leaves(magnus), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * float(np.abs(b).max()))


@pytest.mark.parametrize("twist", [False, True])
def test_order_step_maps_are_exact(twist):
    """Order continuation starts ``PolynomialCurvature(k)`` from the embedded equilibrium of
    order ``k - 1``: the embedding (a zero top coefficient per strain component) must give the
    same configuration, and truncation must undo it."""
    from pacjax._statics.continuation import order_step

    segment = pj.Segment(0.1, 0.01, 500.0, linear_density=0.2)
    scene = pj.Scene(pj.Robot([segment, segment]), pj.PolynomialCurvature(3, twist=twist))
    step = order_step(scene)
    assert step.low == pj.PolynomialCurvature(2, twist=twist)
    assert step.scene.n_dofs == scene.n_dofs - (6 if twist else 4)
    q_low = np.random.default_rng(0).normal(size=(4, step.scene.n_dofs))
    q = step.embed(q_low)
    assert q.shape == (4, scene.n_dofs)
    np.testing.assert_array_equal(step.truncate(q), q_low)
    sites = [(0, 0.3), (0, 1.0), (1, 0.5), (1, 1.0)]
    for a, b in zip(q_low, q, strict=True):
        np.testing.assert_allclose(
            pj.markers(scene, jnp.asarray(b), sites),
            pj.markers(step.scene, jnp.asarray(a), sites),
            atol=1e-12,
        )
        assert float(scene.elastic_energy(jnp.asarray(b))) == pytest.approx(
            float(step.scene.elastic_energy(jnp.asarray(a))), rel=1e-12
        )
    assert order_step(pj.Scene(pj.Robot([segment]), pj.PolynomialCurvature(1))) is None
    assert order_step(pj.Scene(pj.Robot([segment]), pj.PAC())) is None


# Jitted once per problem structure (a lambda jitted inside the loop compiled at every pass);
# the solver's linearisation and the autodiff one in one program (one compilation, not two).
_linearisations = eqx.filter_jit(
    lambda p, x: (p.linearise(x), (jax.jacfwd(p.residual)(x), p.residual(x), p.energy(x)))
)


@pytest.mark.parametrize(
    "model", [pj.PAC(), slow(pj.PCC(frame="paper")), slow(pj.PolynomialCurvature(2))], ids=repr
)
def test_follower_force_jacobian_as_dead_force_plus_turning_is_the_autodiff_one(model):
    """Follower forces only: the Jacobian from the dead-force Hessian plus the turning of the
    forces (``follower_jacobian``) equals ``jax.jacfwd`` of the residual, and the residual and
    energy are the solver's own. ``PolynomialCurvature`` keeps the forward derivative of the
    forces (its frames move with the knots), so its problem carries no dead scene."""
    from pacjax._model.inputs import static_load_sites
    from pacjax._statics.problem import ScaledProblem

    loads = (
        pj.PointForce((0.5, -0.3, 2.0), segment=1, s=1.0, follower=True),
        pj.PointForce((0.0, 0.8, -0.4), segment=0, s=0.6, follower=True),
    )
    scene = pj.presets.stella2023(model, n_sections=2, loads=loads, quadrature_points=4)
    scene = static_load_sites(scene)
    u = jnp.asarray(np.random.default_rng(3).uniform(0.0, 0.01, scene.n_tendons))
    # Compiled: op by op, the scene's constants took ~250 small compilations.
    problem = eqx.filter_jit(ScaledProblem.build)(scene, u)
    assert (problem.dead_scene is None) == isinstance(model, pj.PolynomialCurvature)
    rng = np.random.default_rng(5)
    for scale in (0.3, 3.0):
        y = jnp.asarray(rng.normal(size=scene.n_dofs)) * scale
        (jac, (r, (merit, _))), (expected, residual, energy) = _linearisations(problem, y)
        r_scale = float(jnp.max(jnp.abs(residual)))
        np.testing.assert_allclose(r, residual, rtol=0, atol=1e-14 * r_scale)
        assert float(merit) == pytest.approx(float(energy), rel=1e-12)
        scale_j = float(jnp.max(jnp.abs(expected)))
        assert float(jnp.max(jnp.abs(jac - expected))) < 1e-10 * scale_j


@pytest.mark.parametrize(
    "model",
    [pj.PAC(), slow(pj.PAC(frame="paper")), pj.PCC(), slow(pj.PCC(frame="paper"))],
    ids=repr,
)
def test_plane_frame_derivatives_are_the_autodiff_ones(model):
    """PCC/PAC knot frames differentiated point by point along the bending and plane angles
    (:func:`pacjax._model.kinematics.segment_knot_jacobian`, :func:`segment_knot_curvature`) equal
    ``jax.jacfwd`` and ``jax.hessian`` of the frames: straight, at 1e-9 rad (where ``phi`` is
    nearly undefined), and bent by several rad; with and without the weighted tangent
    integral; with an empty padding interval at the end. On the dynamics' knot grid
    (:data:`pacjax.dynamics.KNOT_GRID`: three position nodes an interval; the statics' four are
    what every other test here takes)."""
    import functools

    import jax.tree_util as jtu

    from pacjax._model.kinematics import segment_knot_frames

    nodes = pj.dynamics.KNOT_GRID[1]
    frames = functools.partial(segment_knot_frames, interval_nodes=nodes)
    rng = np.random.default_rng(0)
    inner = np.sort(rng.uniform(0.0, 1.0, 9))
    knots = jnp.asarray(np.concatenate([[0.0], inner, [1.0, 1.0]]))
    d = model.dofs_per_segment()
    weights = jnp.asarray(rng.uniform(0.0, 1.0, (len(knots) - 1, nodes)))
    length = jnp.asarray(0.12)
    for bend in (0.0, 1e-9, 1.0, 4.0):
        q = jnp.asarray(
            np.concatenate([rng.normal(0.0, bend, d - 2), [rng.uniform(-3, 3)], [0.004]])
        )
        for node_weights in (weights, None):
            shapes = jax.eval_shape(frames, model, q, length, knots, node_weights)
            lam = jtu.tree_map(lambda x: jnp.asarray(rng.normal(size=x.shape)), shapes)
            value, val, jac, jac_ad, hess, hess_ad = _knot_frame_derivatives(
                model, q, length, knots, node_weights, lam, nodes
            )
            for got, want in zip(jtu.tree_leaves(val), jtu.tree_leaves(value), strict=True):
                np.testing.assert_array_equal(got, want)
            for got, want in zip(jtu.tree_leaves(jac), jtu.tree_leaves(jac_ad), strict=True):
                np.testing.assert_allclose(got, want, rtol=0, atol=1e-14 * np.abs(want).max())
            assert np.abs(hess_ad).max() > 0
            np.testing.assert_allclose(hess, hess_ad, rtol=0, atol=1e-14 * np.abs(hess_ad).max())


def _spec_rotation(frame, theta, phi):
    """The spec's ``Rz(phi) Ry(theta) [Rz(-phi)]`` written out entry by entry."""
    ct, st, cp, sp = jnp.cos(theta), jnp.sin(theta), jnp.cos(phi), jnp.sin(phi)
    if frame == "paper":
        return jnp.array([[cp * ct, -sp, cp * st], [sp * ct, cp, sp * st], [-st, 0.0, ct]])
    v = ct - 1.0
    return jnp.array(
        [
            [1 + cp * cp * v, cp * sp * v, cp * st],
            [cp * sp * v, 1 + sp * sp * v, sp * st],
            [-cp * st, -sp * st, ct],
        ]
    )


@pytest.mark.parametrize("frame", ["torsion_free", "paper"])
def test_plane_rotation_jet_is_the_spec_rotation_and_its_derivatives(frame):
    """``R = B0 + sin(theta) B1 + (1 - cos theta) B2`` and its derivatives along
    ``(theta, phi)`` up to the second equal the spec's matrix and its automatic derivatives."""
    model = pj.PAC(frame=frame)
    theta = jnp.asarray([0.0, 1e-9, 0.3, -2.0, 3.0])
    phi = jnp.asarray(0.7)
    jet = jax.jit(lambda t, p: model.plane_rotation_jet(t, p, order=2))(theta, phi)
    spec = jax.jit(
        jax.vmap(
            lambda t: (
                _spec_rotation(frame, t, phi),
                jax.jacfwd(_spec_rotation, (1, 2))(frame, t, phi),
                jax.hessian(_spec_rotation, (1, 2))(frame, t, phi),
            )
        )
    )(theta)
    value, (d_t, d_p), ((d_tt, d_tp), (_, d_pp)) = spec
    for got, want in zip(jet, (value, d_t, d_p, d_tt, d_tp, d_pp), strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)


@eqx.filter_jit
def _knot_frame_derivatives(model, q, length, knots, node_weights, lam, nodes):
    """The knot frames, and their first and second derivatives both written out and by
    autodiff, in one program (compiled once per model and weighting, not op by op)."""
    import jax.tree_util as jtu

    from pacjax._model.kinematics import (
        segment_knot_curvature,
        segment_knot_frames,
        segment_knot_jacobian,
    )

    def frames(y):
        return segment_knot_frames(model, y, length, knots, node_weights, interval_nodes=nodes)

    def pull(y):
        pairs = zip(jtu.tree_leaves(lam), jtu.tree_leaves(frames(y)), strict=True)
        return sum(jnp.sum(a * b) for a, b in pairs)

    jac, val = segment_knot_jacobian(model, q, length, knots, node_weights, interval_nodes=nodes)
    hess = segment_knot_curvature(model, q, length, knots, node_weights, lam, interval_nodes=nodes)
    return frames(q), val, jac, jax.jacfwd(frames)(q), hess, jax.hessian(pull)(q)


@pytest.mark.parametrize(
    "model",
    [
        pj.PAC(),
        slow(pj.PAC(frame="paper")),
        slow(pj.PCC()),
        slow(pj.PolynomialCurvature(order=1, twist=True)),
    ],
    ids=repr,
)
def test_structured_hessian_with_written_out_tendon_chords_is_the_autodiff_one(model):
    """On the paper's robot every tendon chord lies in one segment, and the solver's Hessian
    takes the chords' derivatives written out (``pacjax._model.tendons.tendon_parts_derivatives``)
    instead of differentiating through them: it must equal ``jax.hessian`` of the potential
    energy to round-off, straight, moderately and strongly bent, with the tendons taut."""
    from pacjax._model.hessian import energy_derivatives

    scene = pj.presets.stella2023(model, tip_mass=0.2)
    assert scene.energy_plan().chords is not None
    rng = np.random.default_rng(3)
    controls = jnp.asarray(rng.uniform(0.005, 0.02, scene.n_tendons))
    # The structured derivatives and the autodiff ones in one program (one compilation).
    derivatives = jax.jit(
        lambda q: (
            energy_derivatives(scene, q, controls),
            jax.grad(scene.potential_energy)(q, controls),
            jax.hessian(scene.potential_energy)(q, controls),
        )
    )
    for scale in (0.0, 0.3, 3.0):
        q = jnp.asarray(rng.uniform(-1.0, 1.0, scene.n_dofs) * scale)
        (_, grad, hess), grad_ad, hess_ad = derivatives(q)
        assert np.abs(hess_ad).max() > 0
        np.testing.assert_allclose(grad, grad_ad, rtol=0, atol=1e-13 * np.abs(grad_ad).max())
        np.testing.assert_allclose(hess, hess_ad, rtol=0, atol=1e-13 * np.abs(hess_ad).max())


# ------------------------------------------------------------------------------ rotations
@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32], ids=["float64", "float32"])
def test_rotation_primitives_against_the_exponential_series_and_smooth_at_zero(dtype):
    """``exp_so3``, ``rotate_ez``, ``cross3`` and ``hat`` on rotation vectors (zero, on
    both sides of the kernels' series threshold, large) against the exponential series and
    ``np.cross``; the first and second derivatives of ``exp_so3`` at zero against the series,
    and ``rotate_ez``'s everywhere against those of ``exp_so3``'s third column."""
    from pacjax._model.rotation import cross3, exp_so3, hat, rotate_ez

    def expm(k):
        term, total = np.eye(3), np.eye(3)
        for n in range(1, 40):
            term = term @ k / n
            total = total + term
        return total

    def skew(o):
        return np.array([[0.0, -o[2], o[1]], [o[2], 0.0, -o[0]], [-o[1], o[0], 0.0]])

    omegas = np.array(
        [
            [0, 0, 0],
            [1e-4, -2e-4, 3e-4],
            [0.018, 0.01, -0.02],  # |w|^2 = 8.2e-4: the series
            [0.025, 0.01, -0.02],  # |w|^2 = 1.1e-3: the closed form
            [0.4, -1.3, 2.2],
        ]
    )
    v = np.array([0.3, -0.2, 1.1])
    tol = 1e-14 if dtype == jnp.float64 else 2e-6
    reference = np.stack([expm(skew(o)) for o in omegas])
    vd = jnp.asarray(v, dtype)
    rot, crossed, hats, first, second = jax.jit(
        lambda w: (
            jax.vmap(exp_so3)(w),
            jnp.stack(cross3(w.T, vd), axis=-1),
            jax.vmap(hat)(w),
            jax.jacfwd(exp_so3)(w[0]),
            jax.hessian(exp_so3)(w[0]),
        )
    )(jnp.asarray(omegas, dtype))
    np.testing.assert_allclose(rot, reference, rtol=0, atol=tol)
    np.testing.assert_allclose(crossed, np.cross(omegas, v), rtol=0, atol=tol)
    np.testing.assert_allclose(hats, np.stack([skew(o) for o in omegas]), rtol=0, atol=tol)
    # At zero: dR/dw_k = [e_k]x, and d2R/dw_j dw_k = ([e_j]x [e_k]x + [e_k]x [e_j]x) / 2.
    generators = np.stack([skew(e) for e in np.eye(3)])
    np.testing.assert_allclose(first, np.moveaxis(generators, 0, -1), rtol=0, atol=tol)
    products = np.einsum("jab,kbc->acjk", generators, generators)
    np.testing.assert_allclose(second, 0.5 * (products + np.swapaxes(products, 2, 3)), atol=tol)
    # exp([w]x) e_z written out, with its first and second derivatives, at every w above.
    w = jnp.asarray(omegas, dtype)

    @jax.jit
    def columns(w):
        return [
            (jax.vmap(fn(lambda x: exp_so3(x)[:, 2]))(w), jax.vmap(fn(rotate_ez))(w))
            for fn in (lambda x: x, jax.jacfwd, jax.hessian)
        ]

    for ez_col, ez in columns(w):
        np.testing.assert_allclose(ez, ez_col, rtol=0, atol=tol)
    np.testing.assert_allclose(rotate_ez(w), reference[:, :, 2], rtol=0, atol=tol)
