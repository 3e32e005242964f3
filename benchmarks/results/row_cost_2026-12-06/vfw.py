import time
exec(open("crba4.py").read())
import pacjax._dynamics.equations as E
orig = E.body_dynamics
def bench(c, *a):
    jax.block_until_ready(c(*a)); ts_ = []
    for r in range(5):
        t = time.perf_counter()
        for _ in range(10): out = c(*a)
        jax.block_until_ready(out); ts_.append((time.perf_counter() - t) / 10)
    return np.median(ts_)
f = lambda q, v: vector_field(0.0, (q, v), (model, u0))[1]
for w in (1, 16, 64):
    q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((w, n)))
    v = jnp.asarray(0.1 * rng.standard_normal((w, n)))
    E.body_dynamics = orig
    c0 = jax.jit(jax.vmap(f)).lower(q, v).compile()
    E.body_dynamics = lambda scene, q, qdot, phi: composite(scene, q, qdot, phi)
    c1 = jax.jit(jax.vmap(f)).lower(q, v).compile()
    r = []
    for rep in range(3):
        r.append((bench(c0, q, v) / w * 1e6, bench(c1, q, v) / w * 1e6))
    print(w, "old/new us a row:", " ".join("%.0f/%.0f" % x for x in r), flush=True)
