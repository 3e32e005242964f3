import sys, time
sys.argv = [sys.argv[0], "1", "vf"]
exec(open("/work/main/benchmarks/results/knot_inertia_2026-12-06/vf_parts.py").read().split("W = [int")[0])
for w in (1, 8, 64):
    q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((w, n)))
    v = jnp.asarray(0.1 * rng.standard_normal((w, n)))
    for kind in ("vf",):
        f = jax.jit(jax.vmap(parts(kind)))
        c = f.lower(q, v).compile()
        ca = c.cost_analysis()
        if isinstance(ca, list): ca = ca[0]
        jax.block_until_ready(c(q, v))
        ts_ = []
        for r in range(5):
            t = time.perf_counter()
            for _ in range(30): out = c(q, v)
            jax.block_until_ready(out); ts_.append((time.perf_counter() - t) / 30)
        m = np.median(ts_)
        print(kind, w, "flops/row %.0f" % (ca.get("flops", 0)/w), "transc/row %.0f" % (ca.get("transcendentals",0)/w), "bytes/row %.0f" % (ca.get("bytes accessed",0)/w), "us/row %.1f" % (m/w*1e6), flush=True)
