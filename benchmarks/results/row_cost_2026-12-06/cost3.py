import sys, time
exec(open("/work/main/benchmarks/results/knot_inertia_2026-12-06/bw_setup.py").read())
lum = I._knot_masses(sc, jnp.float64)
print("knots", lum.knots.s.shape, "min_intervals", sc.kinematics.min_intervals)
fr = I._knot_world_frames(sc, lum.knots)
extra = {
 "knotjac": lambda q, v: sum(x.sum() for x in I._knot_jacobians(sc, q, lum.knots)),
 "segframes": lambda q, v: sum(x.sum() for x in I._segment_frames(sc, q, lum.knots)),
 "acc": lambda q, v: sum(x.sum() for x in I._site_accelerations(fr, q, v)),
 "frames1": lambda q, v: sum(x.sum() for x in fr(q)),
 "framesjvp": lambda q, v: sum(x.sum() for x in jax.jvp(fr, (q,), (v,))[1]),
}
for kind in sys.argv[1].split(":"):
    w = 1
    q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((w, n)))
    v = jnp.asarray(0.1 * rng.standard_normal((w, n)))
    fn = extra.get(kind) or parts(kind)
    f = jax.jit(jax.vmap(fn))
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
    print(f"{kind:10s} flops {ca.get('flops',0):9.0f} bytes {ca.get('bytes accessed',0):9.0f} us {m*1e6:6.1f}", flush=True)
