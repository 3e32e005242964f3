import time, sys, re, collections, jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
import pacjax as pj, equinox as eqx
from pacjax._dynamics.equations import EquationsOfMotion
from pacjax._model import inertia as I
from pacjax._model.inertia import PHI_INERTIA_FACTOR
STEP = np.array([0.04, 0, 0, 0, 0, 0, 0, 0, 0.0])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(9))
damping = pj.Damping.modal(scene)
traj = pj.simulate(scene, (0.0, 0.1), STEP, q0=start.q, saveat=np.array([0.0, 0.1]), damping=damping)
q = jnp.asarray(np.asarray(traj.q)[-1]); qd = jnp.asarray(np.asarray(traj.qdot)[-1])
from pacjax._dynamics.simulate import prepare
sc, damping, *_ = prepare(scene, 0.0, 0.5, np.array([0.0, 0.5]), damping, None, 1e-4, 1e-6, 10000, False, PHI_INERTIA_FACTOR, None)
model = EquationsOfMotion.build(sc, damping, PHI_INERTIA_FACTOR, jnp.float64)
u = jnp.asarray(STEP); ud = jnp.zeros(9)

def count(f, *args):
    txt = jax.jit(f).lower(*args).compile().as_text()
    entry = txt[txt.index("ENTRY"):]
    ops = collections.Counter(re.findall(r"= \S+ (\w[\w-]*)\(", entry))
    return sum(v for k, v in ops.items() if k not in ("parameter", "constant", "bitcast", "get-tuple-element", "tuple")), ops

def timeit(f, args, N=2000, reps=5):
    @jax.jit
    def loop(*a):
        def body(i, c):
            r = f(*c)
            tot = sum(jnp.sum(x) for x in jax.tree_util.tree_leaves(r))
            return (c[0] + 1e-14 * tot,) + tuple(c[1:])
        return jax.lax.fori_loop(0, N, body, tuple(a))
    jax.block_until_ready(loop(*args))
    ts = []
    for _ in range(reps):
        t = time.perf_counter(); jax.block_until_ready(loop(*args)); ts.append(time.perf_counter() - t)
    return np.median(ts) / N * 1e6, min(ts) / N * 1e6
