exec(open('./breakdown.py').read().split('print(pj.__file__')[0])
print("quadrature points", sc.quadrature_points if hasattr(sc, "quadrature_points") else None)
for name, fn, a in [("vf one", jax.jit(lambda y: vector_field(0.0, y, args)), (y0,)),
                    ("vf 64", jax.jit(jax.vmap(lambda y: vector_field(0.0, y, args))), (ys,))]:
    c = fn.lower(*a).compile()
    ca = c.cost_analysis()
    ca = ca[0] if isinstance(ca, list) else ca
    print(name, {k: ca[k] for k in ca if k in ("flops", "bytes accessed", "transcendentals")})
    txt = c.as_text()
    print(name, "hlo lines", len(txt.splitlines()), "fusions", txt.count(" fusion("), "custom-calls", txt.count("custom-call("), "whiles", txt.count(" while("))
