"""The vector field's cost, pacjax against SoRoMoX, on vs_soromox.py's tentacle (problem a)."""
import sys, time, numpy as np, jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
import equinox as eqx, pacjax as pj
sys.path.insert(0, "benchmarks")
import vs_soromox as V
from pacjax._dynamics.equations import EquationsOfMotion
from pacjax._dynamics.simulate import prepare
from pacjax._model.inertia import PHI_INERTIA_FACTOR

prob = V.PROBLEMS["a"]
scene = V.pacjax_scene(prob, pj.PAC())
robot = V.soromox_robot(prob)
u = jnp.asarray([4.0, 2.0])
# pacjax: the state 0.05 s into a simulation after the tensions are applied.
damping = pj.Damping.modal(scene)
traj = pj.simulate(scene, (0.0, 0.05), np.asarray(u), saveat=np.array([0.0, 0.05]), damping=damping)
q = jnp.asarray(np.asarray(traj.q)[-1]); qd = jnp.asarray(np.asarray(traj.qdot)[-1])
sc, damping, *_ = prepare(scene, 0.0, 0.5, np.array([0.0, 0.5]), damping, None, 1e-4, 1e-6, 10000, False, PHI_INERTIA_FACTOR, None)
model = EquationsOfMotion.build(sc, damping, PHI_INERTIA_FACTOR, jnp.float64)
ud = jnp.zeros(2)
# SoRoMoX: a state of the same size of motion (its coordinates differ).
n_s = robot.num_internal_dofs if hasattr(robot, "num_internal_dofs") else None
print("pacjax dofs", q.shape[0], "SoRoMoX dofs", n_s, "actuators", robot.num_actuators, flush=True)
rng = np.random.default_rng(0)
ys = jnp.concatenate([1e-1 * jnp.asarray(rng.standard_normal(n_s)), 1e-1 * jnp.asarray(rng.standard_normal(n_s))])
sx_vf = lambda y: robot.forward_dynamics(0.0, y, (u,))
px_vf = lambda y: jnp.concatenate([y[q.shape[0]:], model.accelerations(y[:q.shape[0]], y[q.shape[0]:], u, ud)])
yp = jnp.concatenate([q, qd])
print("finite", bool(jnp.all(jnp.isfinite(jax.jit(sx_vf)(ys)))), bool(jnp.all(jnp.isfinite(jax.jit(px_vf)(yp)))), flush=True)

def timeit(f, y0, w, N):
    Y = y0 + 1e-3 * jnp.asarray(rng.standard_normal((w, y0.shape[0])))
    g = jax.vmap(f)
    @jax.jit
    def loop(Y):
        return jax.lax.fori_loop(0, N, lambda i, Y: Y + 1e-14 * jnp.sum(g(Y), axis=1, keepdims=True), Y)
    t = time.perf_counter(); jax.block_until_ready(loop(Y)); c = time.perf_counter() - t
    ts = []
    for _ in range(5):
        t = time.perf_counter(); jax.block_until_ready(loop(Y)); ts.append(time.perf_counter() - t)
    return np.median(ts) / N / w * 1e6, c

for r in range(2):
    for w in (1, 64):
        N = 2000 if w == 1 else 40
        for name, f, y0 in (("pacjax PAC", px_vf, yp), ("SoRoMoX GVS", sx_vf, ys)):
            t, c = timeit(f, y0, w, N)
            print(f"round {r} width {w:2d} {name:12s} {t:8.1f} us a row (compile {c:.1f} s)", flush=True)
