import time, sys, jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
import pacjax as pj, equinox as eqx
from pacjax._dynamics.equations import EquationsOfMotion
from pacjax._model.inertia import PHI_INERTIA_FACTOR
STEP = np.array([0.04, 0, 0, 0, 0, 0, 0, 0, 0.0])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(9))
damping = pj.Damping.modal(scene)
traj = pj.simulate(scene, (0.0, 0.1), STEP, q0=start.q, saveat=np.array([0.0, 0.1]), damping=damping)
q = jnp.asarray(np.asarray(traj.q)[-1]); qd = jnp.asarray(np.asarray(traj.qdot)[-1])
from pacjax._dynamics.simulate import prepare
sc, damping, *_ = prepare(scene, 0.0, 0.5, np.array([0.0, 0.5]), damping, None, 1e-4, 1e-6, 10000, False, PHI_INERTIA_FACTOR, None)
model = EquationsOfMotion.build(sc, damping, PHI_INERTIA_FACTOR, jnp.float64)
u = jnp.asarray(STEP); ud = jnp.zeros(9)
widths = [int(a) for a in sys.argv[1:]] or [1, 8, 32, 64]
for w in widths:
    N = max(20, 2000 // w)
    rng = np.random.default_rng(0)
    Q = q + 1e-3 * jnp.asarray(rng.standard_normal((w, q.shape[0])))
    V = qd + 1e-3 * jnp.asarray(rng.standard_normal((w, q.shape[0])))
    f = jax.vmap(lambda m, q, v: m.accelerations(q, v, u, ud), in_axes=(None, 0, 0))
    @eqx.filter_jit
    def loop(m, Q, V):
        def body(i, c):
            Q, V = c
            r = f(m, Q, V)
            return Q + 1e-14 * jnp.sum(r, axis=1, keepdims=True), V
        return jax.lax.fori_loop(0, N, body, (Q, V))
    t = time.perf_counter(); jax.block_until_ready(loop(model, Q, V)); c = time.perf_counter() - t
    ts = []
    for _ in range(5):
        t = time.perf_counter(); jax.block_until_ready(loop(model, Q, V)); ts.append(time.perf_counter() - t)
    print(f"width {w:3d}: {np.median(ts)/N/w*1e6:8.1f} us a row (min {min(ts)/N/w*1e6:.1f}; compile {c:.1f} s)", flush=True)
