"""Energy, gradient and Hessian of a conservative scene from its per-segment structure.

The potential energy is ``V(q) = E_el(q) + Psi(L_0(q_0), ..., L_{n-1}(q_{n-1}))``: segment ``i``'s
local kinematics ``L_i`` (its frames at the knots, in its own base frame, and the weighted
tangent integral of its weight) depends on its own coordinates ``q_i`` only; ``Psi`` (chaining
the segments, tendon lengths, weight, loads) is cheap. Hence, exactly,

``d2V = d2E_el + J^T (d2 Psi) J + blockdiag_i( d2 (lambda_i . L_i)(q_i) )``

with ``J_i = dL_i / dq_i`` (forward mode, ``d`` directions per segment) and
``lambda = dPsi / dL``. The expensive kinematics is differentiated twice along the ``d``
coordinates of its own segment only, instead of along all ``n d`` coordinates of the robot as a
plain ``jax.hessian`` does; the ``n d`` directions go through the cheap ``Psi`` alone. For PCC
and PAC, whose frames depend on ``q_i`` only through the bending angle (linear in the
curvatures) and the plane angle, ``J_i`` and ``d2 (lambda_i . L_i)`` come from derivatives along
those two angles point by point (:func:`pacjax._model.kinematics.segment_knot_jacobian`): on the
paper's robot with PAC the linearisation took 63-65 instead of 73-77 us per row.

``L_i`` also holds each tendon's length inside segment ``i`` when every chord of the routing
lies in one segment (:class:`pacjax._model.tendons.LocalChords`): a chord's length does not depend
on where its segment is; so does a channel's (:mod:`pacjax._model.channels`), whose length in a
segment depends on that segment's strain alone. ``Psi`` then sums those parts and needs world
frames only at the mass and force sites, so its Hessian along the ``n d`` directions is a small
fraction of the total. The chords' own derivatives are written out from the knot frames' (the
chord ends are affine in the frames; :func:`pacjax._model.tendons.tendon_parts_derivatives`), and
their pull on the frames joins the frames' curvature term: differentiating through the chords
took a third of the time.
"""

from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
from jaxtyping import Array, Float

from .._config import MATMUL_PRECISION
from .kinematics import contract, index_runs, jacobian_and_value
from .loads import PointForce, PointMoment
from .rotation import hat, matvec3
from .scene import Scene, SceneConstants
from .tendons import tendon_parts_derivatives
from .values import known_sites


def _contract(jac, delta):
    """``J delta`` for one leaf: ``jac`` (..., d) times ``delta`` (d,)."""
    return jnp.tensordot(jac, delta, axes=1, precision=MATMUL_PRECISION)


def elastic_hessian(
    scene: Scene, coords: Float[Array, "n d"], consts: SceneConstants
) -> Float[Array, "nd nd"]:
    """Hessian of the elastic energy along the full per-segment layout (``coords``, pinned
    coordinates included), a sum of per-segment terms each in its own segment's coordinates:
    block diagonal, so the ``d`` directions ``e_j`` taken in every segment at once give all its
    blocks (``d`` forward derivatives of the gradient instead of ``n d``)."""
    n, d = coords.shape
    x = coords.reshape(-1)
    grad = jax.grad(lambda y: scene.coords_elastic_energy(y.reshape(n, d), consts))

    def column(tangent):
        return jax.jvp(grad, (x,), (tangent,))[1]

    tangents = jnp.tile(jnp.eye(d, dtype=x.dtype), (1, n))
    columns = jax.vmap(column)(tangents).reshape(d, n, d)  # [j, i, k] = H_i[k, j]
    return jax.scipy.linalg.block_diag(*[columns[:, i].T for i in range(n)])


class _Linearised(NamedTuple):
    """Each segment's local kinematics ``L_i`` and its Jacobian ``J_i``, and the frames at
    traced load sites (their own ``L`` and ``J``)."""

    frame_inputs: tuple  # the per-segment inputs of the frames (Scene.segment_inputs)
    chords: Any  # the chords' inputs, or None
    channels: Any  # the channels' inputs, or None
    frames: tuple  # every knot frame per segment: (rotations, positions)
    chord_derivatives: Any  # tendon parts and their derivatives, or None
    values: tuple  # L_i: (rotations, positions, moments, tendon parts or None)
    jacobians: tuple  # J_i, leaf by leaf
    traced_sites: tuple  # segment of each traced load site
    traced_values: tuple
    traced_jacobians: tuple


def _linearise(scene: Scene, coords, plan, consts, dtype) -> _Linearised:
    """``L_i`` and ``J_i`` of every segment: the frames by forward derivatives, and the tendon
    parts (when every chord lies in one segment) written out from the frames'
    (:func:`pacjax._model.tendons.tendon_parts_derivatives`): as automatic derivatives through
    the chords they were a third of :func:`energy_derivatives`' time."""
    *frame_inputs, chords, channels = scene.segment_inputs(plan, consts, dtype)
    f_jac, f_val = jax.vmap(scene.segment_frames_jacobian)(coords, *frame_inputs)
    chord_d = None
    parts = parts_jac = None
    if chords is not None:
        chord_d = jax.vmap(lambda v, j, ch: tendon_parts_derivatives(v[0], v[1], j[0], j[1], ch))(
            f_val, f_jac, chords
        )
        parts, parts_jac = chord_d.parts, chord_d.jacobian
    if channels is not None:
        # The channels' parts are a small function of the segment's coordinates alone.
        c_jac, c_val = jax.vmap(
            lambda y, length, ch: jacobian_and_value(
                lambda x: scene.segment_channel_lengths(x, length, ch), y
            )
        )(coords, frame_inputs[0], channels)
        parts = c_val if parts is None else parts + c_val
        parts_jac = c_jac if parts_jac is None else parts_jac + c_jac
    traced = [
        jacobian_and_value(lambda y, k=k, s_k=s_k: scene.traced_local_frame(y, k, s_k), coords[k])
        for k, s_k in plan.points.traced
    ]
    return _Linearised(
        frame_inputs=tuple(frame_inputs),
        chords=chords,
        channels=channels,
        frames=(f_val[0], f_val[1]),
        chord_derivatives=chord_d,
        values=(*f_val, parts),
        jacobians=(*f_jac, parts_jac),
        traced_sites=tuple(k for k, _ in plan.points.traced),
        traced_values=tuple(v for _, v in traced),
        traced_jacobians=tuple(j for j, _ in traced),
    )


def _on_load_rows(plan, x: tuple) -> tuple:
    """The frames (and their derivatives) of ``x`` at the knot rows that ``Psi`` reads."""
    runs = index_runs(plan.load_rows)

    def rows(y):
        return jnp.concatenate([y[:, a:b] for a, b in runs], axis=1)

    return (rows(x[0]), rows(x[1]), *x[2:])


def energy_derivatives(
    scene: Scene, q: Float[Array, " n_dofs"], controls, consts: SceneConstants | None = None
) -> tuple[Float[Array, ""], Float[Array, " n_dofs"], Float[Array, "n_dofs n_dofs"]]:
    """``(V, dV/dq, d2V/dq2)`` of a scene at ``q`` (exact, structured; see module docstring).

    ``consts``: :meth:`Scene.constants`, when already computed.
    """
    consts = scene.constants(q.dtype) if consts is None else consts
    coords = scene.coordinates(q)
    n, d = coords.shape
    # Along the full per-segment layout; the pinned coordinates are dropped at the end.
    e_el, g_el = jax.value_and_grad(lambda x: scene.coords_elastic_energy(x.reshape(n, d), consts))(
        coords.reshape(-1)
    )
    h_el = elastic_hessian(scene, coords, consts)
    plan = scene.energy_plan()
    if plan is None:
        return e_el, *_free(scene, g_el, h_el)

    lin = _linearise(scene, coords, plan, consts, q.dtype)
    # Psi reads the knot frames at a few rows only (the segment ends and the world points), so
    # it is differentiated on those rows (the paper's robot with PAC reads 1 row of 10): the
    # buffers written per row fell from 541 to 442 kB, the time by 2-12 % (40 interleaved calls).
    row_plan = plan.on_load_rows()
    seg_val, seg_jac = _on_load_rows(plan, lin.values), _on_load_rows(plan, lin.jacobians)

    def psi(local):
        return scene.load_energy(local, controls, row_plan, consts)

    e_load, (lam_seg, lam_traced) = jax.value_and_grad(psi)((seg_val, lin.traced_values))

    # Gradient: J^T lambda, segment by segment.
    grad = jax.vmap(contract)(lam_seg, seg_jac)
    for k, lt, jt in zip(lin.traced_sites, lam_traced, lin.traced_jacobians, strict=True):
        grad = grad.at[k].add(contract(lt, jt))

    # J^T d2Psi J: the Hessian of Psi along the linearised kinematics.
    def psi_linear(delta):
        delta = delta.reshape(n, d)
        seg = jtu.tree_map(lambda v, j: v + jax.vmap(_contract)(j, delta), seg_val, seg_jac)
        tr = tuple(
            jtu.tree_map(lambda v, j, k=k: v + _contract(j, delta[k]), tv, tj)
            for k, tv, tj in zip(
                lin.traced_sites, lin.traced_values, lin.traced_jacobians, strict=True
            )
        )
        return psi((seg, tr))

    h_load = jax.hessian(psi_linear)(jnp.zeros(n * d, q.dtype))
    h_curv = _curvature(scene, coords, plan, lin, lam_seg, lam_traced)
    hessian = h_el + h_load + h_curv
    return e_el + e_load, *_free(scene, g_el + grad.reshape(n * d), hessian)


def _free(scene: Scene, grad, hessian):
    """The gradient and Hessian along the coordinates (:meth:`Scene.free_coordinates`)."""
    free = scene.free_coordinates()
    if free is None:
        return grad, hessian
    return grad[free], hessian[np.ix_(free, free)]


def _curvature(scene: Scene, coords, plan, lin: _Linearised, lam_seg, lam_traced):
    """``blockdiag_i d2 (lambda_i . L_i)(q_i)``: per segment, along its own coordinates. The
    tendon parts add their Hessian along the frames' linearisation and their pull on the
    frames; a traced load site adds its own frame's."""
    n = coords.shape[0]
    # Back from Psi's rows to every knot: a constant one-hot product, not a scatter.
    embed = np.eye(plan.knots.width)[:, plan.load_rows]

    def curvature(qi, lam_i, cd, rot, pos, ch, channels, *frame_args):
        lam_rot, lam_pos, lam_moment, lam_parts = lam_i
        # Psi's weights on every knot (zero off its rows).
        e = jnp.asarray(embed, rot.dtype)
        lam_frames = (
            jnp.einsum("kr,rij->kij", e, lam_rot, precision=MATMUL_PRECISION),
            jnp.einsum("kr,ri->ki", e, lam_pos, precision=MATMUL_PRECISION),
            lam_moment,
        )
        h_parts = 0.0
        if cd is not None:
            h_parts, (g_rot, g_pos) = cd.curvature(lam_parts, rot, pos, ch)
            lam_frames = (lam_frames[0] + g_rot, lam_frames[1] + g_pos, lam_frames[2])
        if channels is not None:
            length = frame_args[0]
            h_parts = h_parts + jax.hessian(
                lambda y: jnp.dot(
                    lam_parts,
                    scene.segment_channel_lengths(y, length, channels),
                    precision=MATMUL_PRECISION,
                )
            )(qi)
        return scene.segment_frames_curvature(qi, tuple(lam_frames), *frame_args) + h_parts

    blocks = jax.vmap(curvature)(
        coords,
        lam_seg,
        lin.chord_derivatives,
        *lin.frames,
        lin.chords,
        lin.channels,
        *lin.frame_inputs,
    )
    for k, s_k, lt in zip(
        lin.traced_sites, (s for _, s in plan.points.traced), lam_traced, strict=True
    ):

        def traced_energy(y, k=k, s_k=s_k, lt=lt):
            return contract(lt, scene.traced_local_frame(y, k, s_k))

        blocks = blocks.at[k].add(jax.hessian(traced_energy)(coords[k]))
    return jax.scipy.linalg.block_diag(*[blocks[i] for i in range(n)])


def dead_followers(scene: Scene) -> tuple[Scene, tuple[int, ...]] | None:
    """``scene`` with each follower force made a dead (world) force, and the indices of those
    loads: the structure of :func:`follower_jacobian`, which sets their forces per call.

    None when the scene has point moments (no such split), no follower force, or a model whose
    frames move with the knots of the kinematics: the dead force's work is evaluated on the
    energy's knots, the residual's follower force on its own knots, and the Jacobian would then
    not be the derivative of the residual to round-off (``PolynomialCurvature(2)``: 4e-9
    relative at curvatures ~1 per segment).
    """
    if scene.loads_of(PointMoment) or not scene.model.frames_independent_of_knots():
        return None
    index = tuple(i for i, x in enumerate(scene.loads) if isinstance(x, PointForce) and x.follower)
    if not index:
        return None
    loads = list(scene.loads)
    for i in index:
        dead = PointForce(np.zeros(3), loads[i].segment, follower=False)
        # The site as it is (a Python float from ``static_load_sites`` takes the knot path).
        loads[i] = eqx.tree_at(lambda f: f.s, dead, loads[i].s)
    return eqx.tree_at(lambda sc: sc.loads, scene, tuple(loads)), index


def follower_jacobian(
    scene: Scene,
    dead_scene: Scene,
    index: tuple[int, ...],
    q: Float[Array, " n_dofs"],
    controls,
    dead_consts: SceneConstants,
):
    """``dF/dq`` of a scene whose only non-conservative loads are follower forces, with
    ``F = grad V - Q`` its residual.

    With the forces ``f_k(q) = R_k(q) f_k^local`` at points ``p_k(q)``, ``Q = sum J_k^T f_k``
    and ``dQ/dq = sum f_k . d2 p_k + J_k^T df_k/dq``. The first term is the Hessian of the work
    of the forces held fixed in the world, which :func:`energy_derivatives` gets from the
    per-segment structure at the cost of a dead force (``dead_scene`` and ``index`` from
    :func:`dead_followers`, ``dead_consts`` the dead scene's constants). The second is
    ``-J_k^T [f_k]x W_k``, with ``W_k`` the angular velocity Jacobian of the frame at ``p_k``.
    The forward derivative of ``Q`` through the whole chain, which this replaces, cost about as
    much as the rest of the Hessian (``benchmarks/RESULTS.md``, "Follower force: the Jacobian
    of PCC/PAC scenes"). The residual itself is not taken from here:
    the dead force's work is evaluated on the energy's knots, ``Q`` on its own, and for PAC the
    two differ by up to 3.7e-12 relative (curvatures of a few rad per segment).
    """
    followers = [scene.loads[i] for i in index]
    segs = np.asarray([f.segment for f in followers])
    sites = known_sites([f.s for f in followers], q.dtype)

    def frames(x):
        rot, pos = scene.frames(x, segs, sites)
        return (rot, pos), (rot, pos)

    (d_rot, d_pos), (rot, pos) = jax.jacfwd(frames, has_aux=True)(q)
    world = matvec3(rot, jnp.stack([f.force for f in followers]).astype(q.dtype))
    # dR/dq_j = [w_j]x R: W (k, 3, n) from the skew part of dR R^T.
    skew = jnp.einsum("kijn,klj->kiln", d_rot, rot, precision=MATMUL_PRECISION)
    omega = jnp.stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]], axis=1)
    forces = iter(world)
    dead_scene = eqx.tree_at(
        lambda sc: [sc.loads[i].force for i in index], dead_scene, [next(forces) for _ in index]
    )
    _, _, hessian = energy_derivatives(dead_scene, q, controls, dead_consts)
    # -J^T df/dq = J^T [f]x W
    hessian = hessian + jnp.einsum(
        "kin,kij,kjm->nm", d_pos, jax.vmap(hat)(world), omega, precision=MATMUL_PRECISION
    )
    return hessian
