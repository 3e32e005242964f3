exec(open("benchmarks/results/vf_cost_2026-12-07/hlo.py").read().split("parts = {")[0])
import re, collections
def roots(f):
    p, s = eqx.partition(model, eqx.is_array)
    txt = jax.jit(lambda p, q, v: f(eqx.combine(p, s), q, v)).lower(p, q, qd).compile().as_text()
    blocks = re.split(r"\n\n", txt); r = {}
    for b in blocks:
        name = b.strip().split("\n")[0].split(" ")[0].lstrip("%")
        m = re.search(r"ROOT \S+ = \S+ ([\w-]+)\(", b)
        if m: r[name] = m.group(1)
    entry = txt[txt.index("ENTRY"):]
    return collections.Counter(r.get(n, "?") for n in re.findall(r"= \S+ fusion\(.*?calls=%?([\w.-]+)", entry))
print("body", roots(lambda m, q, v: I.body_dynamics(m.scene, q, v)).most_common(8))
print("forces", roots(lambda m, q, v: m.forces(q, v, u, ud, jnp.eye(12))).most_common(8))
print("grad", roots(lambda m, q, v: jax.grad(m.scene.potential_energy)(q, u)).most_common(8))
print("energy", roots(lambda m, q, v: m.scene.potential_energy(q, u)).most_common(8))
