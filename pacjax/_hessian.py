"""Energy, gradient and Hessian of a conservative scene from its per-segment structure.

The potential energy is ``V(q) = E_el(q) + Psi(L_0(q_0), ..., L_{n-1}(q_{n-1}))``: segment ``i``'s
local kinematics ``L_i`` (its frames at the knots, in its own base frame, and the weighted
tangent integral of its weight) depends on its own coordinates ``q_i`` only; ``Psi`` (chaining
the segments, tendon lengths, weight, loads) is cheap. Hence, exactly,

``d2V = d2E_el + J^T (d2 Psi) J + blockdiag_i( d2 (lambda_i . L_i)(q_i) )``

with ``J_i = dL_i / dq_i`` (forward mode, ``d`` directions per segment) and
``lambda = dPsi / dL``. The expensive kinematics is differentiated twice along the ``d``
coordinates of its own segment only, instead of along all ``n d`` coordinates of the robot as a
plain ``jax.hessian`` does; the ``n d`` directions go through the cheap ``Psi`` alone.

``L_i`` also holds each tendon's length inside segment ``i`` when every chord of the routing
lies in one segment (:class:`pacjax._tendons.LocalChords`): a chord's length does not depend on
where its segment is. ``Psi`` then sums those parts and needs world frames only at the mass and
force sites, so its Hessian along the ``n d`` directions is a small fraction of the total.
"""

import jax
import jax.numpy as jnp
import jax.tree_util as jtu
from jaxtyping import Array, Float

from ._scene import Scene, SceneConstants


def _contract(jac, delta):
    """``J delta`` for one leaf: ``jac`` (..., d) times ``delta`` (d,)."""
    return jnp.tensordot(jac, delta, axes=1)


def energy_derivatives(
    scene: Scene, q: Float[Array, " n_dofs"], controls, consts: SceneConstants | None = None
) -> tuple[Float[Array, ""], Float[Array, " n_dofs"], Float[Array, "n_dofs n_dofs"]]:
    """``(V, dV/dq, d2V/dq2)`` of a scene at ``q`` (exact, structured; see module docstring).

    ``consts``: :meth:`Scene.constants`, when already computed.
    """
    n_dofs = q.shape[0]
    consts = scene.constants(q.dtype) if consts is None else consts
    e_el, g_el = jax.value_and_grad(scene.elastic_energy)(q, consts)
    h_el = jax.hessian(scene.elastic_energy)(q, consts)
    plan = scene._energy_plan()
    if plan is None:
        return e_el, g_el, h_el

    coords = scene.coordinates(q)
    n, d = coords.shape
    dtype = q.dtype
    inputs = scene._segment_inputs(plan, consts, dtype)
    segment = scene._segment_local

    def value_and_jacobian(f, x):
        jac, out = jax.jacfwd(lambda y: (f(y), f(y)), has_aux=True)(x)
        return jac, out

    seg_jac, seg_val = jax.vmap(
        lambda qi, *args: value_and_jacobian(lambda y: segment(y, *args), qi)
    )(coords, *inputs)
    traced_sites = [k for k, _ in plan.points.traced]
    traced = [
        value_and_jacobian(lambda y, k=k, s_k=s_k: scene._traced_local(y, k, s_k), coords[k])
        for k, s_k in plan.points.traced
    ]
    traced_val = tuple(v for _, v in traced)
    traced_jac = tuple(j for j, _ in traced)

    def psi(local):
        return scene._load_energy(local, controls, plan, consts)

    local = (seg_val, traced_val)
    e_load, lam = jax.value_and_grad(psi)(local)
    lam_seg, lam_traced = lam

    # Gradient: J^T lambda, segment by segment.
    def pull(lam_tree, jac_tree):
        leaves = zip(jtu.tree_leaves(lam_tree), jtu.tree_leaves(jac_tree), strict=True)
        return sum(jnp.tensordot(lt, jt, axes=lt.ndim) for lt, jt in leaves)

    grad = jax.vmap(pull)(lam_seg, seg_jac)
    for k, lt, jt in zip(traced_sites, lam_traced, traced_jac, strict=True):
        grad = grad.at[k].add(pull(lt, jt))

    # J^T d2Psi J: the Hessian of Psi along the linearised kinematics.
    def psi_linear(delta):
        delta = delta.reshape(n, d)
        seg = jtu.tree_map(lambda v, j: v + jax.vmap(_contract)(j, delta), seg_val, seg_jac)
        tr = tuple(
            jtu.tree_map(lambda v, j, k=k: v + _contract(j, delta[k]), tv, tj)
            for k, tv, tj in zip(traced_sites, traced_val, traced_jac, strict=True)
        )
        return psi((seg, tr))

    h_load = jax.hessian(psi_linear)(jnp.zeros(n * d, dtype))

    # lambda . d2L: per segment, along its own coordinates.
    def curvature(qi, lam_i, *args):
        return jax.hessian(lambda y: pull(lam_i, segment(y, *args)))(qi)

    blocks = jax.vmap(curvature)(coords, lam_seg, *inputs)
    for k, s_k, lt in zip(
        traced_sites, (s for _, s in plan.points.traced), lam_traced, strict=True
    ):
        f = lambda y, k=k, s_k=s_k, lt=lt: pull(lt, scene._traced_local(y, k, s_k))  # noqa: E731
        blocks = blocks.at[k].add(jax.hessian(f)(coords[k]))
    h_curv = jax.scipy.linalg.block_diag(*[blocks[i] for i in range(n)])

    hessian = h_el + h_load + h_curv
    return e_el + e_load, g_el + grad.reshape(n_dofs), hessian
