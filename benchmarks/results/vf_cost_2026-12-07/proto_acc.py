"""Timing prototype: the accelerations at zero qddot from each segment's local second derivative
along its own velocities, chained rigidly (a_p = a_e + alpha x r + w x (w x r) + 2 w x v_rel +
a_rel), against the nested jvp of the chained frames (`_site_accelerations`)."""
import time, jax, jax.numpy as jnp, numpy as np, equinox as eqx
jax.config.update("jax_enable_x64", True)
import pacjax as pj
from pacjax._model import inertia as I
from pacjax._dynamics import equations as E
from pacjax._dynamics.simulate import prepare
from pacjax._model.rotation import matmul3, matvec3
STEP = np.array([0.04, 0, 0, 0, 0, 0, 0, 0, 0.0])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
damping = pj.Damping.modal(scene)
sc, damping, *_ = prepare(scene, 0.0, 0.5, np.array([0.0, 0.5]), damping, None, 1e-4, 1e-6, 10000, False, I.PHI_INERTIA_FACTOR, None)
model = E.EquationsOfMotion.build(sc, damping, I.PHI_INERTIA_FACTOR, jnp.float64)
q = jnp.zeros(12).at[0].set(0.3).at[4].set(0.2).at[8].set(-0.4).at[2].set(0.5).at[1].set(-0.2); qd = jnp.linspace(-0.3, 0.4, 12)
knots = I._knot_masses(sc, jnp.float64).knots

def current(m, q, v):
    return I._site_accelerations(I._knot_world_frames(m.scene, knots), q, v)

def vee(a):
    return I._vee_skew(a)

def chained(m, q, v):
    scene = m.scene
    coords, vc = scene.coordinates(q), scene.coordinates(v)
    lengths = scene.robot.stacked("length").astype(q.dtype)
    grid = jnp.asarray(knots.s, q.dtype)
    def local(qi, vi, li, ki):
        f = lambda x: scene._segment_frames(x, li, ki, None)[:2]
        def first(x):
            return jax.jvp(f, (x,), (vi,))
        (val, d1), (_, d2) = jax.jvp(first, (qi,), (vi,))
        return val, d1, d2
    (rho, x), (rho_d, x_d), (rho_dd, x_dd) = jax.vmap(local)(coords, vc, lengths, grid)
    w_loc = vee(jnp.matmul(rho_d, jnp.swapaxes(rho, -1, -2)))        # (n, k, 3) in the base frame
    a_loc = vee(jnp.matmul(rho_dd, jnp.swapaxes(rho, -1, -2)))
    R = jnp.asarray(scene.robot.base_rotation, q.dtype); P = jnp.asarray(scene.robot.base_position, q.dtype)
    W = jnp.zeros(3, q.dtype); V = jnp.zeros(3, q.dtype); Al = jnp.zeros(3, q.dtype); A = jnp.zeros(3, q.dtype)
    om, acc, alp = [], [], []
    for i in range(coords.shape[0]):
        r = matvec3(R, x[i]); rel_v = matvec3(R, x_d[i]); rel_a = matvec3(R, x_dd[i])
        w_rel = matvec3(R, w_loc[i]); al_rel = matvec3(R, a_loc[i])
        vel = V + jnp.cross(W, r) + rel_v
        a = A + jnp.cross(Al, r) + jnp.cross(W, jnp.cross(W, r)) + 2 * jnp.cross(W, rel_v) + rel_a
        w = W + w_rel
        al = Al + jnp.cross(W, w_rel) + al_rel
        Rp = matmul3(R, rho[i])
        RpT = jnp.swapaxes(Rp, -1, -2)
        om.append(matvec3(RpT, w)); alp.append(matvec3(RpT, al)); acc.append(a)
        R, P = Rp[-1], P + r[-1]
        W, V, Al, A = w[-1], vel[-1], al[-1], a[-1]
    return jnp.concatenate(om), jnp.concatenate(acc), jnp.concatenate(alp)

a = eqx.filter_jit(current)(model, q, qd); b = eqx.filter_jit(chained)(model, q, qd)
for name, x, y in zip(["omega", "acc", "alpha"], a, b):
    print(name, float(jnp.max(jnp.abs(x - y))), float(jnp.max(jnp.abs(x))))
import re, collections
def count(f):
    p, s = eqx.partition(model, eqx.is_array)
    txt = jax.jit(lambda p, q, v: f(eqx.combine(p, s), q, v)).lower(p, q, qd).compile().as_text()
    entry = txt[txt.index("ENTRY"):]
    ops = collections.Counter(re.findall(r"= \S+ (\w[\w-]*)\(", entry))
    return sum(v for k, v in ops.items() if k not in ("parameter", "constant", "bitcast", "get-tuple-element", "tuple"))
print("kernels current", count(current), "chained", count(chained))
N = 2000
for name, f in [("current", current), ("chained", chained)] * 3:
    @eqx.filter_jit
    def loop(m, q, v, f=f):
        def body(i, c):
            q, v = c
            r = sum(jnp.sum(t) for t in f(m, q, v))
            return q + 1e-14 * r, v + 1e-14 * r
        return jax.lax.fori_loop(0, N, body, (q, v))
    jax.block_until_ready(loop(model, q, qd))
    ts = []
    for _ in range(7):
        t = time.perf_counter(); jax.block_until_ready(loop(model, q, qd)); ts.append(time.perf_counter() - t)
    print(f"{name:10s} {np.median(ts)/N*1e6:7.1f} us (min {min(ts)/N*1e6:.1f})", flush=True)
