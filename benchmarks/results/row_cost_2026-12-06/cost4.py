exec(open("/work/main/benchmarks/results/knot_inertia_2026-12-06/bw_setup.py").read())
lum = I._knot_masses(sc, jnp.float64)
q = jnp.asarray(start.q); v = jnp.asarray(0.1 * rng.standard_normal(n))
jp, ja = I._knot_jacobians(sc, q, lum.knots)
def f(jp, ja):
    return I._mass_from_jacobians(sc, jp, ja, lum.masses, lum.moments, 1e-6)
c = jax.jit(f).lower(jp, ja).compile(); ca = c.cost_analysis(); ca = ca[0] if isinstance(ca, list) else ca
print("M assembly flops", ca["flops"], "J shapes", jp.shape)
