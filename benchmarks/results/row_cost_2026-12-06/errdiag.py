exec(open("hist.py").read().split("sol = run(q0)")[0])
from jax.flatten_util import ravel_pytree
sol = run(q0)
t = np.asarray(sol.ts); ok = np.isfinite(t); t = t[ok]
Q = np.asarray(sol.ys[0])[ok]; V = np.asarray(sol.ys[1])[ok]
term = diffrax.ODETerm(S._TRACED_VECTOR_FIELD)
fresh = dataclasses.replace(solver, reuse=1)
@jax.jit
def trystep(q, v, h):
    y = (q, v)
    st = fresh.init(term, 0.0, h, y, (model, STEP))
    y1, err, _, _, _ = fresh.step(term, 0.0, h, y, (model, STEP), st, False)
    x0, _ = ravel_pytree(y); x1, _ = ravel_pytree(y1); e, _ = ravel_pytree(err)
    scale = 1e-6 + 1e-4 * jnp.maximum(jnp.abs(x0), jnp.abs(x1))
    return e / scale
for tt in (0.15, 0.25, 0.38, 0.40, 0.42):
    k = np.searchsorted(t, tt)
    r = np.asarray(trystep(jnp.asarray(Q[k]), jnp.asarray(V[k]), 1e-3))
    idx = np.argsort(-np.abs(r))[:4]
    print(round(t[k],3), "rms %.2f" % np.sqrt(np.mean(r**2)), [(int(i), round(float(r[i]),2)) for i in idx], "v", np.round(V[k],3).tolist())
