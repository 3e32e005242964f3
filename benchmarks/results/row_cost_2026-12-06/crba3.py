exec(open("/work/main/benchmarks/results/knot_inertia_2026-12-06/bw_setup.py").read())
from pacjax._model.rotation import cross3, matvec3
from pacjax._config import MATMUL_PRECISION as mm

def crossv(a, b):
    return jnp.stack(cross3(tuple(a[..., i] for i in range(3)), tuple(b[..., i] for i in range(3))), axis=-1)

def _after(x):
    """Sums over the segments after each one (zero after the last)."""
    total = jnp.cumsum(x[::-1], axis=0)[::-1]
    return total - x

def composite(scene, q, qdot, phi_inertia=1e-6):
    lumped = I._knot_masses(scene, q.dtype)
    f = I._segment_frames(scene, q, lumped.knots)
    n, k, _, d = f.d_pos.shape
    m = lumped.masses.reshape(n, k)
    mom = lumped.moments.reshape(n, k, 3)
    x, R = f.world_pos, f.world_rot
    own_pos = jnp.einsum("iab,ipbk->ipka", f.base_rot, f.d_pos, precision=mm)
    own_ang = I._vee_skew(jnp.einsum("ipba,ipbck->ipkac", f.rot, f.d_rot, precision=mm))
    end_w = I._vee_skew(jnp.einsum("jabk,jcb->jkac", f.d_rot[:, -1], f.rot[:, -1], precision=mm))
    end_w = jnp.einsum("jab,jkb->jka", f.base_rot, end_w, precision=mm)  # (n, d, 3)
    end_t = own_pos[:, -1] - crossv(end_w, x[:, -1][:, None, :])  # about the world origin
    # own columns on own knots
    m_pos = m[:, :, None, None] * own_pos
    i_ang = mom[:, :, None, :] * own_ang
    m_own = jnp.einsum("ipka,ipla->ikl", own_pos, m_pos, precision=mm) + jnp.einsum("ipka,ipla->ikl", own_ang, i_ang, precision=mm)
    # what an own column's motion weighs against a rigid twist (w, t) of an earlier segment: w.F_w + t.F_t
    f_w = (crossv(x[:, :, None, :], m_pos) + matvec3(R[:, :, None], i_ang)).sum(1)  # (n, d, 3)
    f_t = m_pos.sum(1)
    # each segment's knots as one rigid body about the origin: (A, c, mass), then all after it
    rot_in = jnp.einsum("ipab,ipb,ipcb->iac", R, mom, R, precision=mm)
    mx = m[..., None] * x
    a_in = jnp.einsum("ipa,ipa->i", mx, x)[:, None, None] * jnp.eye(3, dtype=q.dtype) - jnp.einsum("ipa,ipb->iab", mx, x, precision=mm) + rot_in
    A, c, ms = _after(a_in), _after(mx.sum(1)), _after(m.sum(1))
    idx = np.maximum(np.arange(n)[:, None], np.arange(n)[None, :])
    Ai, ci, mi = A[idx], c[idx], ms[idx]  # (n, n, ...)
    w, t = end_w, end_t
    wj, wk = w[:, None, :, None, :], w[None, :, None, :, :]  # (j, k, x, y, 3)
    tj, tk = t[:, None, :, None, :], t[None, :, None, :, :]
    Aw = jnp.sum(Ai[:, :, None, None] * wk[..., None, :], axis=-1)  # A w_k
    cc = ci[:, :, None, None, :]
    rigid = jnp.sum(
        wj * Aw + wj * crossv(cc, tk) + wk * crossv(cc, tj) + mi[:, :, None, None, None] * tj * tk,
        axis=-1,
    )
    sf = jnp.sum(wj * f_w[None, :, None, :, :] + tj * f_t[None, :, None, :, :], axis=-1)
    upper = jnp.asarray(np.triu(np.ones((n, n)), 1), q.dtype)[:, :, None, None]
    diag = jnp.asarray(np.eye(n), q.dtype)[:, :, None, None]
    mb = rigid + upper * sf + jnp.swapaxes(jnp.swapaxes(upper * sf, 0, 1), 2, 3) + diag * m_own[:, None]
    M = jnp.swapaxes(mb, 1, 2).reshape(n * d, n * d)
    free = scene.free_coordinates()
    if free is not None:
        M = M[free][:, free]
    extra = I.coordinate_inertia(scene, q.dtype, phi_inertia)
    if extra is not None:
        M = M + jnp.diag(extra)
    frames = I._knot_world_frames(scene, lumped.knots)
    omega, acc, alpha = I._site_accelerations(frames, q, qdot)
    acc, alpha, omega = (z.reshape(n, k, 3) for z in (acc, alpha, omega))
    euler = mom * alpha + crossv(omega, mom * omega)
    ma = m[..., None] * acc
    b_own = jnp.einsum("ipka,ipa->ik", own_pos, ma, precision=mm) + jnp.einsum("ipka,ipa->ik", own_ang, euler, precision=mm)
    wr_w = _after((crossv(x, ma) + matvec3(R, euler)).sum(1))
    wr_t = _after(ma.sum(1))
    bias = b_own + jnp.einsum("jka,ja->jk", w, wr_w, precision=mm) + jnp.einsum("jka,ja->jk", t, wr_t, precision=mm)
    return 0.5 * (M + M.T), scene.free_part(bias)
