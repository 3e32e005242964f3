import sys, time
sys.argv = [sys.argv[0], "1", "vf"]
exec(open("/work/main/benchmarks/results/knot_inertia_2026-12-06/vf_parts.py").read().split("W = [int")[0])
import pacjax._model.inertia as I
out = [I.__file__.split("/")[2]]
for kind in ("vf", "body"):
    q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((1, n)))
    v = jnp.asarray(0.1 * rng.standard_normal((1, n)))
    c = jax.jit(jax.vmap(parts(kind))).lower(q, v).compile()
    jax.block_until_ready(c(q, v)); ts_ = []
    for r in range(7):
        t = time.perf_counter()
        for _ in range(50): o = c(q, v)
        jax.block_until_ready(o); ts_.append((time.perf_counter() - t) / 50)
    out.append("%s %.1f us" % (kind, np.median(ts_) * 1e6))
print(" ".join(out))
