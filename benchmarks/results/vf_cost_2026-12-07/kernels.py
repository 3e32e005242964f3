exec(open("benchmarks/results/vf_cost_2026-12-07/hlo.py").read().split("parts = {")[0])
import re, collections
def count(f):
    p, s = eqx.partition(model, eqx.is_array)
    txt = jax.jit(lambda p, q, v: f(eqx.combine(p, s), q, v)).lower(p, q, qd).compile().as_text()
    entry = txt[txt.index("ENTRY"):]
    ops = collections.Counter(re.findall(r"= \S+ (\w[\w-]*)\(", entry))
    return sum(v for k, v in ops.items() if k not in ("parameter", "constant", "bitcast", "get-tuple-element", "tuple"))
lm = lambda m, x: I._knot_masses(m.scene, x.dtype)
fr = lambda m, x: I._knot_world_frames(m.scene, lm(m, x).knots)
parts = {
 "world frames at the knots": lambda m, q, v: fr(m, q)(q),
 "  one jvp": lambda m, q, v: jax.jvp(fr(m, q), (q,), (v,)),
 "  accelerations (nested jvp)": lambda m, q, v: I._site_accelerations(fr(m, q), q, v),
 "segments' local frames + Jacobians": lambda m, q, v: I._segment_frames(m.scene, q, lm(m, q).knots),
 "knot Jacobians": lambda m, q, v: I._knot_jacobians(m.scene, q, lm(m, q).knots),
 "M": lambda m, q, v: I.mass_matrix(m.scene, q),
 "M and C qdot": lambda m, q, v: I.body_dynamics(m.scene, q, v),
 "tendon lengths": lambda m, q, v: m.scene.tendon_lengths(q),
 "potential": lambda m, q, v: m.scene.potential_energy(q, u),
 "potential's gradient": lambda m, q, v: jax.grad(m.scene.potential_energy)(q, u),
 "forces": lambda m, q, v: m.forces(q, v, u, ud, jnp.eye(12)),
 "vector field": lambda m, q, v: m.accelerations(q, v, u, ud),
}
for k, f in parts.items():
    print(f"{k:40s} {count(f)}")
