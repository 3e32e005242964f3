import time, numpy as np, jax, jax.numpy as jnp, equinox as eqx
import pacjax as pj
from pacjax._statics.problem import ScaledProblem
from pacjax._statics.equilibrium import make_solver, start_point
from pacjax._statics.options import SolverOptions
from pacjax._statics.modes import stiffness_modes
from pacjax._statics import equilibrium as E
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
n = 128
u = jnp.asarray(np.random.default_rng(0).uniform(0, 0.02, (n, 9)))
sol = pj.solve_batch(scene, np.asarray(u))
q = jnp.asarray(sol.q) * 0.9
opts = E.resolve_options(SolverOptions(), jnp.float64) if hasattr(E, "resolve_options") else SolverOptions()
def prob(uu): return ScaledProblem.build(scene, uu)
@jax.jit
def lin(u, q):
    return jax.vmap(lambda uu, qq: prob(uu).linearise(qq / prob(uu).sigma))(u, q)
@jax.jit
def energy(u, q):
    return jax.vmap(lambda uu, qq: prob(uu).energy(qq / prob(uu).sigma))(u, q)
@jax.jit
def modes(J, w):
    return jax.vmap(lambda j, ww: stiffness_modes(j, ww, 0.05, 1e-8))(J, w)
@jax.jit
def moved(u, q, d):
    return jax.vmap(lambda uu, qq, dd: prob(uu).moved(qq / prob(uu).sigma, dd))(u, q, d)
J, (r, (m, w)) = lin(u, q)
def t(f, *a, k=20):
    jax.block_until_ready(f(*a))
    ts=[]
    for _ in range(k):
        t0=time.perf_counter(); jax.block_until_ready(f(*a)); ts.append(time.perf_counter()-t0)
    return np.median(ts)/n*1e6
print("us per row: linearise %.1f energy %.1f modes %.1f moved %.1f" % (t(lin,u,q), t(energy,u,q), t(modes,J,w), t(moved,u,q,r*0.01)))
