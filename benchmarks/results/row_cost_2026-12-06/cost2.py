import sys, time
exec(open("/work/main/benchmarks/results/knot_inertia_2026-12-06/bw_setup.py").read())
from pacjax._model.energy import strain_rate_energy
extra = {
 "potgrad": lambda q, v: jax.grad(model.passive.potential_energy)(q, u0),
 "tlen": lambda q, v: sc.tendon_lengths(q),
 "tlen_jvp": lambda q, v: jax.jvp(sc.tendon_lengths, (q,), (v,))[1],
 "pot": lambda q, v: sc.potential_energy(q, jnp.zeros(9)),
 "knotframes": lambda q, v: sum(x.sum() for x in jax.tree_util.tree_leaves(sc.knot_grid_frames(q, I._knot_masses(sc, q.dtype).knots if hasattr(I, "_knot_masses") else None))),
}
for kind in sys.argv[1].split(":"):
    w = 1
    q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((w, n)))
    v = jnp.asarray(0.1 * rng.standard_normal((w, n)))
    try:
        fn = extra.get(kind) or parts(kind)
        f = jax.jit(jax.vmap(fn))
        c = f.lower(q, v).compile()
    except Exception as e:
        print(kind, "ERR", repr(e)[:200]); continue
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
