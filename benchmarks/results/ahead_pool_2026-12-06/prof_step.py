import time, sys, numpy as np, jax, jax.numpy as jnp
import pacjax as pj
from pacjax._statics.problem import ScaledProblem
from pacjax._statics.modes import stiffness_modes
which = sys.argv[1]
if which == "paper":
    scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2); hi = 0.02
else:
    scene = pj.presets.tentacle(model=pj.PolynomialCurvature(1) if which == "poly1" else pj.PAC()); hi = 2.0
n = 128
u = jnp.asarray(np.random.default_rng(0).uniform(0, hi, (n, scene.n_tendons)))
sol = pj.solve_batch(scene, np.asarray(u), progress=False)
q = jnp.asarray(sol.q) * 0.9
def prob(uu): return ScaledProblem.build(scene, uu)
@jax.jit
def lin(u, q):
    return jax.vmap(lambda uu, qq: prob(uu).linearise(qq / prob(uu).sigma))(u, q)
@jax.jit
def energy(u, q):
    return jax.vmap(lambda uu, qq: prob(uu).energy(qq / prob(uu).sigma))(u, q)
@jax.jit
def resid(u, q):
    return jax.vmap(lambda uu, qq: ScaledProblem.root_fn(qq / prob(uu).sigma, prob(uu)))(u, q)
@jax.jit
def modes(J, w):
    return jax.vmap(lambda j, ww: stiffness_modes(j, ww, 0.05, 1e-8))(J, w)
J, (r, (m, w)) = lin(u, q)
def t(f, *a, k=20):
    jax.block_until_ready(f(*a))
    ts=[]
    for _ in range(k):
        t0=time.perf_counter(); jax.block_until_ready(f(*a)); ts.append(time.perf_counter()-t0)
    return np.median(ts)/n*1e6
print(which, "us per row: linearise %.1f energy %.1f residual %.1f modes %.1f" % (t(lin,u,q), t(energy,u,q), t(resid,u,q), t(modes,J,w)))
