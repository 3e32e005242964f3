import re, collections
exec(open("crba4.py").read())
def kinds(fn):
    q = jnp.asarray(np.asarray(start.q)[None]); v = jnp.asarray(0.1 * rng.standard_normal((1, n)))
    txt = jax.jit(jax.vmap(fn)).lower(q, v).compile().as_text()
    body = txt[txt.index("\nENTRY"):]; body = body[:body.index("\n}")]
    c = collections.Counter()
    for l in body.splitlines()[1:]:
        mt = re.search(r"= \S+ ([a-z\-]+)\(", l)
        if mt and mt.group(1) not in ("parameter", "bitcast", "get-tuple-element", "constant", "tuple"):
            c[mt.group(1)] += 1
    return dict(c)
print("struct", kinds(lambda q, v: I.structured_body_dynamics(sc, q, v, 1e-6)))
print("composite", kinds(lambda q, v: composite(sc, q, v)))
