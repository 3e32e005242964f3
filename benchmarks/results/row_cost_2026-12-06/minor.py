import sys, time
sys.argv = [sys.argv[0], "1", "vf"]
exec(open("/work/main/benchmarks/results/knot_inertia_2026-12-06/vf_parts.py").read().split("W = [int")[0])
def bench(c, *a):
    jax.block_until_ready(c(*a)); ts_ = []
    for r in range(5):
        t = time.perf_counter()
        for _ in range(20): out = c(*a)
        jax.block_until_ready(out); ts_.append((time.perf_counter() - t) / 20)
    return np.median(ts_)
for w in (1, 64):
    q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((w, n)))
    v = jnp.asarray(0.1 * rng.standard_normal((w, n)))
    f0 = jax.jit(jax.vmap(parts("vf")))
    f1 = jax.jit(jax.vmap(parts("vf"), in_axes=1, out_axes=1))
    m0 = bench(f0, q, v); m1 = bench(f1, q.T, v.T)
    print(w, "major %.1f us/row" % (m0/w*1e6), "minor %.1f us/row" % (m1/w*1e6), flush=True)
