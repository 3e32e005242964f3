"""Prototype: M and C qdot from the segments' composite inertias (no (knots, n_dofs, 3) Jacobians)."""
import sys, time
exec(open("/work/main/benchmarks/results/knot_inertia_2026-12-06/bw_setup.py").read())
from pacjax._model.rotation import cross3, matvec3
from pacjax._config import MATMUL_PRECISION as mm

def crossv(a, b):
    return jnp.stack(cross3(tuple(a[..., i] for i in range(3)), tuple(b[..., i] for i in range(3))), axis=-1)

def composite(scene, q, qdot, phi_inertia=1e-6):
    lumped = I._knot_masses(scene, q.dtype)
    f = I._segment_frames(scene, q, lumped.knots)
    n, k, _, d = f.d_pos.shape
    m = lumped.masses.reshape(n, k)
    mom = lumped.moments.reshape(n, k, 3)
    x = f.world_pos  # (n, k, 3)
    R = f.world_rot  # (n, k, 3, 3)
    # own columns: world velocities and body angular velocities (n, k, d, 3)
    own_pos = jnp.einsum("iab,ipbk->ipka", f.base_rot, f.d_pos, precision=mm)
    own_ang = I._vee_skew(jnp.einsum("ipba,ipbck->ipkac", f.rot, f.d_rot, precision=mm))
    # each segment's end twist per coordinate about the world origin: (w, t - w x e)
    end_ang = I._vee_skew(jnp.einsum("jabk,jcb->jkac", f.d_rot[:, -1], f.rot[:, -1], precision=mm))
    end_ang = jnp.einsum("jab,jkb->jka", f.base_rot, end_ang, precision=mm)  # (n, d, 3)
    e = x[:, -1]  # (n, 3)
    end_lin = own_pos[:, -1] - crossv(end_ang, e[:, None, :])
    S = jnp.concatenate([end_ang, end_lin], axis=-1)  # (n, d, 6)
    # own-own blocks
    own_rot = mom[:, :, None, :] * own_ang
    M_own = jnp.einsum("ipka,ip,ipla->ikl", own_pos, m, own_pos, precision=mm) + jnp.einsum("ipka,ipla->ikl", own_ang, own_rot, precision=mm)
    # wrench of each own column about the origin, summed over the segment's knots: (n, d, 6)
    ang_w = matvec3(R[:, :, None], own_rot)  # R (I a) world
    lin = m[:, :, None, None] * own_pos
    F = jnp.concatenate([(crossv(x[:, :, None, :], lin) + ang_w).sum(1), lin.sum(1)], axis=-1)
    # spatial inertia of each segment's knots about the origin, then of everything beyond each segment
    xx = jnp.einsum("ipa,ipb->ipab", x, x)
    r2 = jnp.sum(x * x, -1)[..., None, None] * jnp.eye(3)
    rot_in = jnp.einsum("ipab,ipb,ipcb->ipac", R, mom, R, precision=mm)
    top = jnp.einsum("ip,ipab->iab", m, r2 - xx) + rot_in.sum(1)
    mx = jnp.einsum("ip,ipa->ia", m, x)
    hatmx = jnp.stack([jnp.stack([jnp.zeros_like(mx[:,0]), -mx[:,2], mx[:,1]], -1), jnp.stack([mx[:,2], jnp.zeros_like(mx[:,0]), -mx[:,0]], -1), jnp.stack([-mx[:,1], mx[:,0], jnp.zeros_like(mx[:,0])], -1)], -2)
    msum = m.sum(1)
    # v = -[x] w + t: Phi = [[m[x]^T[x] + RIR^T, m[x]], [m[x]^T... ]]
    Phi = jnp.concatenate([jnp.concatenate([top, hatmx], -1), jnp.concatenate([-hatmx, msum[:, None, None] * jnp.eye(3)], -1)], -2)
    beyond = jnp.cumsum(Phi[::-1], axis=0)[::-1]
    beyond = jnp.concatenate([beyond[1:], jnp.zeros_like(beyond[:1])])  # segments after i
    idx = np.maximum(np.arange(n)[:, None], np.arange(n)[None, :])
    T = jnp.einsum("jxa,jkab,kyb->jkxy", S, beyond[idx], S, precision=mm)
    SF = jnp.einsum("jxa,kya->jkxy", S, F, precision=mm)
    upper = jnp.asarray(np.triu(np.ones((n, n)), 1), q.dtype)[:, :, None, None]
    diag = jnp.asarray(np.eye(n), q.dtype)[:, :, None, None]
    Mb = T + upper * SF + jnp.swapaxes(jnp.swapaxes(upper * SF, 0, 1), 2, 3) + diag * M_own[:, None]
    M = jnp.swapaxes(Mb, 1, 2).reshape(n * d, n * d)
    free = scene.free_coordinates()
    if free is not None:
        M = M[free][:, free]
    extra = I.coordinate_inertia(scene, q.dtype, phi_inertia)
    if extra is not None:
        M = M + jnp.diag(extra)
    # bias
    frames = I._knot_world_frames(scene, lumped.knots)
    omega, acc, alpha = I._site_accelerations(frames, q, qdot)
    acc = acc.reshape(n, k, 3); alpha = alpha.reshape(n, k, 3); omega = omega.reshape(n, k, 3)
    euler = mom * alpha + crossv(omega, mom * omega)
    b_own = jnp.einsum("ipka,ip,ipa->ik", own_pos, m, acc, precision=mm) + jnp.einsum("ipka,ipa->ik", own_ang, euler, precision=mm)
    ma = m[..., None] * acc
    wr = jnp.concatenate([(crossv(x, ma) + matvec3(R, euler)).sum(1), ma.sum(1)], -1)  # (n, 6)
    wr_beyond = jnp.cumsum(wr[::-1], 0)[::-1]
    wr_beyond = jnp.concatenate([wr_beyond[1:], jnp.zeros_like(wr_beyond[:1])])
    bias = b_own + jnp.einsum("jka,ja->jk", S, wr_beyond)
    bias = scene.free_part(bias)
    return 0.5 * (M + M.T), bias

q = jnp.asarray(np.asarray(start.q) + 0.05 * rng.standard_normal(n)); v = jnp.asarray(rng.standard_normal(n))
M0, b0 = jax.jit(lambda q, v: I.structured_body_dynamics(sc, q, v, 1e-6))(q, v)
M1, b1 = jax.jit(lambda q, v: composite(sc, q, v))(q, v)
print("M err", float(jnp.abs(M1 - M0).max()), float(jnp.abs(M0).max()), "b err", float(jnp.abs(b1 - b0).max()), float(jnp.abs(b0).max()))
for name, fn in (("struct", lambda q, v: I.structured_body_dynamics(sc, q, v, 1e-6)), ("composite", composite_fn := (lambda q, v: composite(sc, q, v)))):
    c = jax.jit(fn).lower(q, v).compile(); ca = c.cost_analysis(); ca = ca[0] if isinstance(ca, list) else ca
    nk = c.as_text().count("\n  ROOT") if False else None
    jax.block_until_ready(c(q, v)); ts_ = []
    for r in range(7):
        t = time.perf_counter()
        for _ in range(30): out = c(q, v)
        jax.block_until_ready(out); ts_.append((time.perf_counter() - t) / 30)
    print(name, "flops", ca["flops"], "us %.1f" % (np.median(ts_) * 1e6))
