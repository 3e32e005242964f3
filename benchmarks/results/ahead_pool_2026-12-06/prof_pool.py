import time, sys, numpy as np, jax, jax.numpy as jnp, equinox as eqx
import jax.tree_util as jtu
import pacjax as pj
from pacjax._statics.problem import ScaledProblem
from pacjax._statics.equilibrium import make_solver, start_point, equilibrium_from
from pacjax._statics.options import SolverOptions, resolve_options
from pacjax._statics.modes import stiffness_modes, saddle_free_step
which = sys.argv[1]
if which == "paper":
    scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2); hi = 0.02
else:
    scene = pj.presets.tentacle(model=pj.PolynomialCurvature(1) if which == "poly1" else pj.PAC()); hi = 2.0
n = 128
U = jnp.asarray(np.random.default_rng(0).uniform(0, hi, (n, scene.n_tendons)))
opts = resolve_options(SolverOptions(), jnp.float64)
solver = make_solver(scene, opts, jnp.float64, ahead=True)
fn = ScaledProblem.root_fn
shared = ScaledProblem.build(scene, U[0])
def prob(u): return eqx.tree_at(lambda pr: pr.controls, shared, u)
@jax.jit
def init(U):
    def one(u):
        p = prob(u)
        y = start_point(p, jnp.zeros(scene.n_dofs), opts)
        f_struct, aux_struct = eqx.filter_eval_shape(fn, y, p)
        st = solver.init(fn, y, p, None, f_struct, aux_struct, frozenset())
        return y, st
    return jax.vmap(one)(U)
@jax.jit
def step(U, Y, S):
    return jax.vmap(lambda u, y, s: solver.step(fn, y, prob(u), None, s, frozenset())[:2])(U, Y, S)
@jax.jit
def pool_like(U, Y, S):
    def one(u, y, s):
        p = prob(u)
        done, _ = solver.terminate(fn, y, p, None, s, frozenset())
        y2, s2, _ = solver.step(fn, y, p, None, s, frozenset())
        run = ~done
        y2 = jnp.where(run, y2, y); s2 = jtu.tree_map(lambda a, b: jnp.where(run, a, b), s2, s)
        eq = equilibrium_from(scene, p, solver, y2, s2, s2.step, opts.tol)
        return y2, s2, eq
    return jax.vmap(one)(U, Y, S)
@jax.jit
def lin(U, Y):
    return jax.vmap(lambda u, y: prob(u).linearise(y))(U, Y)
@jax.jit
def resid(U, Y):
    return jax.vmap(lambda u, y: fn(y, prob(u)))(U, Y)
@jax.jit
def modes(J, w):
    return jax.vmap(lambda j, ww: stiffness_modes(j, ww, 0.05, 1e-8))(J, w)
@jax.jit
def moved(U, Y, D):
    return jax.vmap(lambda u, y, d: prob(u).moved(y, d))(U, Y, D)
Y, S = init(U)
for _ in range(2):
    Y, S = step(U, Y, S)
J, (r, (m, w)) = lin(U, Y)
def t(f, *a, k=20):
    jax.block_until_ready(f(*a)); ts = []
    for _ in range(k):
        t0 = time.perf_counter(); jax.block_until_ready(f(*a)); ts.append(time.perf_counter() - t0)
    return np.median(ts) / n * 1e6
print(which, "us/row: step %.1f pool-like %.1f | linearise %.1f residual %.1f modes %.1f moved %.1f" % (
    t(step, U, Y, S), t(pool_like, U, Y, S), t(lin, U, Y), t(resid, U, Y), t(modes, J, w), t(moved, U, Y, r * 0.01)))
