import sys, time
sys.argv = [sys.argv[0], "1", "vf"]
exec(open("/work/main/benchmarks/results/knot_inertia_2026-12-06/vf_parts.py").read().split("W = [int")[0])
def bench(c, *a):
    jax.block_until_ready(c(*a)); ts_ = []
    for r in range(5):
        t = time.perf_counter()
        for _ in range(10): out = c(*a)
        jax.block_until_ready(out); ts_.append((time.perf_counter() - t) / 10)
    return np.median(ts_)
res = []
for w in (1, 16, 64):
    q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((w, n)))
    v = jnp.asarray(0.1 * rng.standard_normal((w, n)))
    f0 = jax.jit(jax.vmap(parts("vf")))
    res.append("w%d %.1f" % (w, bench(f0, q, v)/w*1e6))
import os
print(os.environ.get("XLA_FLAGS"), " ".join(res), flush=True)
