import time, sys, numpy as np, jax, jax.numpy as jnp
import jax.tree_util as jtu
import pacjax as pj
from pacjax._model.kinematics import contract, jacobian_and_value
scene = pj.presets.tentacle(model=pj.PolynomialCurvature(1))
n = 128
rng = np.random.default_rng(0)
consts = scene.constants(jnp.float64)
plan = scene.energy_plan()
*fi, chords, channels = scene.segment_inputs(plan, consts, jnp.float64)
nseg, d = scene.coordinates(jnp.zeros(scene.n_dofs)).shape
Q = jnp.asarray(rng.normal(0, 0.5, (n, nseg, d)))
frames = lambda y, *a: scene._segment_frames(y, *a)
val = jax.vmap(frames)(Q[0], *fi)
LAM = jtu.tree_map(lambda v: jnp.asarray(rng.normal(size=(n,) + v.shape)), val)
def timeit(name, f, *args):
    f = jax.jit(f); jax.block_until_ready(f(*args)); ts = []
    for _ in range(30):
        t0 = time.perf_counter(); jax.block_until_ready(f(*args)); ts.append(time.perf_counter() - t0)
    print(f"{name:34s} {np.median(ts)/n*1e6:7.1f} us/row", flush=True)
def jac(q):
    return jax.vmap(lambda y, *a: jacobian_and_value(lambda x: frames(x, *a), y))(q, *fi)
def hes(q, lam):
    return jax.vmap(lambda y, l, *a: jax.hessian(lambda x: contract(l, frames(x, *a)))(y))(q, lam, *fi)
def both(q, lam):
    return jac(q), hes(q, lam)
def fused(q, lam):
    def one(y, l, *a):
        def f(x):
            v, pull = jax.vjp(lambda z: frames(z, *a), x)
            g = pull(l)[0]
            return (v, g), v
        (jv, jg), v = jax.jacfwd(f, has_aux=True)(y)
        return jv, v, jg
    return jax.vmap(one)(q, lam, *fi)
V = jax.vmap
timeit("frames value", V(lambda q: jax.vmap(frames)(q, *fi)), Q)
timeit("frames jacobian", V(jac), Q)
timeit("pairing hessian", V(hes), Q, LAM)
timeit("both", V(both), Q, LAM)
timeit("fused jacfwd(value, vjp)", V(fused), Q, LAM)
a = V(both)(Q, LAM); b = V(fused)(Q, LAM)
print(float(jnp.max(jnp.abs(a[1] - b[2]))), [float(jnp.max(jnp.abs(x - y))) for x, y in zip(jtu.tree_leaves(a[0][0]), jtu.tree_leaves(b[0]))])
