import time, sys, jax, jax.numpy as jnp, numpy as np, equinox as eqx
jax.config.update("jax_enable_x64", True)
import pacjax as pj
from pacjax._dynamics import equations as E
from pacjax._model import inertia as I
from pacjax._dynamics.simulate import prepare
STEP = np.array([0.04, 0, 0, 0, 0, 0, 0, 0, 0.0])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
damping = pj.Damping.modal(scene)
sc, damping, *_ = prepare(scene, 0.0, 0.5, np.array([0.0, 0.5]), damping, None, 1e-4, 1e-6, 10000, False, I.PHI_INERTIA_FACTOR, None)
model = E.EquationsOfMotion.build(sc, damping, I.PHI_INERTIA_FACTOR, jnp.float64)
u = jnp.asarray(STEP); ud = jnp.zeros(9)
q = jnp.zeros(12).at[0].set(0.3).at[4].set(0.2).at[8].set(-0.4).at[2].set(0.5).at[3].set(0.01); qd = jnp.ones(12) * 0.1

def vf(m, x):
    return jnp.concatenate([x[12:], m.accelerations(x[:12], x[12:], u, ud)])

def differences(m, q, v):
    x = jnp.concatenate([q, v]); f0 = vf(m, x)
    h = jnp.sqrt(jnp.finfo(x.dtype).eps) * jnp.maximum(jnp.abs(x), 1.0)
    cols = jax.lax.map(lambda i: (vf(m, x.at[i].add(h[i])) - f0) / h[i], jnp.arange(24))
    return cols.T

def analytic(m, q, v):
    qdd = m.accelerations(q, v, u, ud)
    stiff = m.stiff_jacobian(q, v, u, ud)  # [[0, I], [M^-1 dF/dq, M^-1 dF/dqd]] without inertia derivs
    def inverse(x):
        mass, bias = I.body_dynamics(m.scene, x[:12], x[12:], m.phi_inertia)
        return mass @ jax.lax.stop_gradient(qdd) + bias
    d_inv = jax.jacfwd(inverse)(jnp.concatenate([q, v]))
    mass = I.mass_matrix(m.scene, q, m.phi_inertia)
    corr = jax.scipy.linalg.cho_solve(jax.scipy.linalg.cho_factor(mass), d_inv)
    return stiff.at[12:].add(-corr)

def stiff_only(m, q, v):
    return m.stiff_jacobian(q, v, u, ud)

a = eqx.filter_jit(differences)(model, q, qd); b = eqx.filter_jit(analytic)(model, q, qd); c = eqx.filter_jit(stiff_only)(model, q, qd)
ex = eqx.filter_jit(lambda m, q, v: jax.jacfwd(lambda x: vf(m, x))(jnp.concatenate([q, v])))(model, q, qd)
sc_ = jnp.max(jnp.abs(ex), axis=0)
print("rel col err: differences", float(jnp.max(jnp.abs(a - ex) / sc_)), "analytic", float(jnp.max(jnp.abs(b - ex) / sc_)), "stiff", float(jnp.max(jnp.abs(c - ex) / sc_)))
N = 100
for name, f in [("differences", differences), ("analytic", analytic), ("stiff", stiff_only)] * 2:
    @eqx.filter_jit
    def loop(m, q, v, f=f):
        def body(i, c):
            q, v = c
            r = f(m, q, v)
            return q + 1e-14 * jnp.sum(r), v + 1e-14 * jnp.sum(r)
        return jax.lax.fori_loop(0, N, body, (q, v))
    t = time.perf_counter(); jax.block_until_ready(loop(model, q, qd)); comp = time.perf_counter() - t
    ts = []
    for _ in range(5):
        t = time.perf_counter(); jax.block_until_ready(loop(model, q, qd)); ts.append(time.perf_counter() - t)
    print(f"{name:12s} {np.median(ts)/N*1e6:8.1f} us (min {min(ts)/N*1e6:.1f}) compile+1 {comp:.1f} s", flush=True)
