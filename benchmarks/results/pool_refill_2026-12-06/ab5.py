# solve_batch with per-row parameters (update): the tip mass per row, paper robot, PAC.
import time, numpy as np, jax, sys, equinox as eqx
import pacjax as pj
from pacjax._statics import pool as P
P.CPU_LANES = int(sys.argv[1]) if len(sys.argv) > 1 else 2
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
def update(sc, m):
    return eqx.tree_at(lambda s: s.loads[4].mass, sc, m)
out = []
for n in (100, 1000):
    rng = np.random.default_rng(0)
    u = rng.uniform(0, 0.02, (n, 9)); m = rng.uniform(0.1, 0.3, n)
    f = lambda: pj.solve_batch(scene, u, params=m, update=update, chunk_size=n, fallback=False, progress=False)
    jax.block_until_ready(f().q)
    ts = []
    for rep in range(5):
        t = time.perf_counter(); sol = f(); jax.block_until_ready(sol.q); ts.append(time.perf_counter()-t)
    out.append(f"n={n} {np.median(ts)*1e3:.1f} ms st {np.mean(sol.steps):.2f} conv {np.mean(sol.converged):.2f}")
print(P.__file__.split('/')[2], "lanes", P.CPU_LANES, " | ".join(out), flush=True)
