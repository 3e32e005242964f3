import time
exec(open("/work/main/benchmarks/results/knot_inertia_2026-12-06/bw_setup.py").read())
from pacjax._dynamics.equations import vector_field_jacobian
q = jnp.asarray(start.q); v = jnp.asarray(0.1 * rng.standard_normal(n))
fv = jax.jit(lambda q, v: vector_field(0.0, (q, v), (model, u0)))
fj = jax.jit(lambda q, v: vector_field_jacobian(0.0, (q, v), (model, u0)))
for name, f in (("vf", fv), ("stiffJ", fj), ("vf", fv), ("stiffJ", fj)):
    jax.block_until_ready(f(q, v)); ts_ = []
    for r in range(5):
        t = time.perf_counter()
        for _ in range(30): out = f(q, v)
        jax.block_until_ready(out); ts_.append((time.perf_counter() - t) / 30)
    print(name, "%.1f us" % (np.median(ts_) * 1e6))
