import time, numpy as np, jax, sys
import pacjax as pj
from pacjax._statics import pool as P
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
out = []
for n in (100, 1000):
    u = np.random.default_rng(0).uniform(0, 0.02, (n, 9))
    f = lambda: pj.solve_batch(scene, u, chunk_size=n, tol=1e-10, fallback=False, progress=False)
    jax.block_until_ready(f().q)
    ts = []
    for rep in range(7):
        t = time.perf_counter(); sol = f(); jax.block_until_ready(sol.q); ts.append(time.perf_counter()-t)
    out.append(f"n={n} {np.median(ts)*1e3:.1f} ms ({n/np.median(ts):.0f} eq/s)")
print(P.__file__.split('/')[2], " | ".join(out))
