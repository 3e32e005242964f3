import sys, time
import numpy as np, jax, jax.numpy as jnp
import pacjax as pj
from pacjax._dynamics.simulate import prepare, default_solver
from pacjax._model import inertia as I
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
sc, dm, opts, span, ts = prepare(scene, 0.0, 0.5, [0.5], damping, default_solver(1e-4), 1e-4, 1e-6, 100000, False, 1e-6, None)
knots, masses, moments = I._site_knots(sc, jnp.float64)
rng = np.random.default_rng(0)
n = scene.n_dofs
kinds = {
 "frames": lambda q, v: I._segment_frames(sc, q, knots).world_pos,
 "site_jac": lambda q, v: I._site_jacobians(sc, q, knots),
 "site_vel": lambda q, v: I._site_velocities(sc, q, v, knots),
 "jvp_vel": lambda q, v: jax.jvp(lambda x: I._site_velocities(sc, x, v, knots), (q,), (v,)),
 "body": lambda q, v: I.structured_body_dynamics(sc, q, v, 1e-6),
}
W = [int(w) for w in sys.argv[1:] if w != "--only"] or [1, 64]
for kind, fn in ([] if "--only" in sys.argv else kinds.items()):
    for w in W:
        q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((w, n)))
        v = jnp.asarray(0.1 * rng.standard_normal((w, n)))
        f = jax.jit(jax.vmap(fn))
        jax.block_until_ready(f(q, v))
        if w == 1:
            txt = f.lower(q, v).compile().as_text()
            nops = sum(1 for l in txt.splitlines() if " = " in l)
        ts_ = []
        for r in range(5):
            t = time.perf_counter()
            for _ in range(50): out = f(q, v)
            jax.block_until_ready(out); ts_.append((time.perf_counter() - t) / 50)
        m = np.median(ts_)
        print(f"{kind:9s} width {w:3d}: {m*1e3:.3f} ms/call, {m/w*1e6:.1f} us/row" + (f"  hlo lines {nops}" if w == 1 else ""), flush=True)
print("---")
def site_frames(x):
    f = I._segment_frames(sc, x, knots)
    return knots.select(f.world_rot), knots.select(f.world_pos)
def acc2(q, v):
    def velocities(x):
        (rot, _), (rot_dot, vel) = jax.jvp(site_frames, (x,), (v,))
        return vel, I._vee_skew(jnp.swapaxes(rot, -1, -2) @ rot_dot)
    return jax.jvp(velocities, (q,), (v,))
def acc1(q, v):
    return jax.jvp(lambda x: I._site_velocities(sc, x, v, knots), (q,), (v,))
for kind, fn in {"jvp2": acc2, "jvp_vel": acc1}.items():
  for w in W:
    q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((w, n)))
    v = jnp.asarray(0.1 * rng.standard_normal((w, n)))
    f = jax.jit(jax.vmap(fn))
    jax.block_until_ready(f(q, v))
    ts_ = []
    for r in range(5):
        t = time.perf_counter()
        for _ in range(50): out = f(q, v)
        jax.block_until_ready(out); ts_.append((time.perf_counter() - t) / 50)
    m = np.median(ts_)
    print(f"{kind:9s} width {w:3d}: {m*1e3:.3f} ms/call, {m/w*1e6:.1f} us/row", flush=True)
q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((3, n))); v = jnp.asarray(0.3 * rng.standard_normal((3, n)))
a = jax.vmap(acc1)(q, v); b = jax.vmap(acc2)(q, v)
print("diff", [float(jnp.max(jnp.abs(x - y))) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b))])
