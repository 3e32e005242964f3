exec(open('benchmarks/results/wide_kinematics_2026-12-07/setup.py').read())
import os
sys.path.insert(0, 'benchmarks/results/wide_kinematics_2026-12-07'); from wide import Wide
lumped = I._knot_masses(sc, jnp.float64)
wd = Wide(sc, lumped, I.coordinate_inertia(sc, jnp.float64))
ref = lambda q, v: I.body_dynamics(sc, q, v)
M0, b0 = ref(q, qd)
M1, b1 = jax.jit(wd.dynamics)(q, qd)
tag = " ".join(f"{k}={os.environ.get(k, '')}" for k in ("MODE", "BAR", "BAR2", "ASSEMBLY"))
print(f"[{tag}] |M - M_ref| {float(jnp.max(jnp.abs(M1 - M0))):.1e} of {float(jnp.max(jnp.abs(M0))):.2f}; "
      f"|Cqd - ref| {float(jnp.max(jnp.abs(b1 - b0))):.1e} of {float(jnp.max(jnp.abs(b0))):.2f}")
for name, f in (("ref ", ref), ("wide", wd.dynamics)):
    c = jax.jit(f).lower(q, qd).compile().cost_analysis()
    print(f"  {name}: {count(f, q, qd)[0]} kernels, {c['flops']:.0f} flops, {c.get('transcendentals', 0):.0f} transcendentals")
for r in range(2):
    for name, f in (("ref ", ref), ("wide", wd.dynamics)):
        med, mn = timeit(f, (q, qd))
        print(f"  round {r} {name}: {med:.1f} us (min {mn:.1f})", flush=True)
