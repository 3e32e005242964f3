import time
import numpy as np, jax, jax.numpy as jnp
import pacjax as pj
from pacjax._dynamics.simulate import prepare, default_solver
from pacjax._dynamics.equations import EquationsOfMotion
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
sc, dm, opts, span, ts = prepare(scene, 0.0, 0.5, [0.5], damping, default_solver(1e-4), 1e-4, 1e-6, 100000, False, 1e-6, None)
model = EquationsOfMotion.build(sc, dm, 1e-6, jnp.float64)
u0 = jnp.asarray(np.array([0.04] + [0.0]*8)); ud = jnp.zeros(9)
def cur(q, v):
    return model.tendon_forces(q, v, u0, ud)
def jac(q, v):
    A = jax.jacfwd(sc.tendon_lengths)(q)
    lengths = sc.tendon_lengths(q)
    t, _ = model._motor_law(lengths, A @ v, u0, ud)
    return -(A.T @ t)
def jv(q, v):
    lengths, rates = jax.jvp(sc.tendon_lengths, (q,), (v,))
    t, _ = model._motor_law(lengths, rates, u0, ud)
    _, pull = jax.vjp(sc.tendon_lengths, q)
    return pull(-t)[0]
def lengths_only(q, v):
    return sc.tendon_lengths(q)
rng = np.random.default_rng(0)
q = jnp.asarray(np.asarray(start.q) + 0.01 * rng.standard_normal(12)); v = jnp.asarray(0.1 * rng.standard_normal(12))
ref = jax.jit(cur)(q, v)
for name, fn in [("cur", cur), ("jacfwd", jac), ("jvp+vjp", jv), ("lengths", lengths_only)]:
    f = jax.jit(fn); out = f(q, v); jax.block_until_ready(out)
    if name != "lengths": print(name, "diff", float(jnp.max(jnp.abs(out - ref))))
    ts_ = []
    for r in range(7):
        t = time.perf_counter()
        for _ in range(200): out = f(q, v)
        jax.block_until_ready(out); ts_.append((time.perf_counter() - t) / 200)
    print(name, f"{np.median(ts_)*1e6:.1f} us", flush=True)
