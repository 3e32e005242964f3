import re
exec(open("crba4.py").read())
q = jnp.asarray(np.asarray(start.q) + 0.05 * rng.standard_normal(n)); v = jnp.asarray(rng.standard_normal(n))
M0, b0 = jax.jit(lambda q, v: I.structured_body_dynamics(sc, q, v, 1e-6))(q, v)
M1, b1 = jax.jit(lambda q, v: composite(sc, q, v))(q, v)
print("M err", float(jnp.abs(M1 - M0).max()), "b err", float(jnp.abs(b1 - b0).max()))
def count(fn):
    q = jnp.asarray(np.asarray(start.q)[None]); v = jnp.asarray(0.1 * rng.standard_normal((1, n)))
    c = jax.jit(jax.vmap(fn)).lower(q, v).compile()
    txt = c.as_text(); ca = c.cost_analysis(); ca = ca[0] if isinstance(ca, list) else ca
    body = txt[txt.index("\nENTRY"):]
    body = body[:body.index("\n}")]
    return sum(1 for l in body.splitlines()[1:] if " = " in l and not re.search(r"= \S+ (parameter|bitcast|get-tuple-element|constant|tuple)\(", l)), ca["flops"]
print("struct", count(lambda q, v: I.structured_body_dynamics(sc, q, v, 1e-6)))
print("composite", count(lambda q, v: composite(sc, q, v)))
import pacjax._dynamics.equations as E
E.body_dynamics = lambda scene, q, qdot, phi: composite(scene, q, qdot, phi)
print("vf composite", count(lambda q, v: vector_field(0.0, (q, v), (model, u0))[1]))
