import time, numpy as np, jax, sys
import pacjax as pj
from pacjax._statics import pool as P
P.CPU_LANES = int(sys.argv[1]) if len(sys.argv) > 1 else 2
out = []
for name, scene, m in [("paper", pj.presets.stella2023(pj.PAC(), tip_mass=0.2), 0.02), ("tentacle", pj.presets.tentacle(), None)]:
    for n in (100, 1000):
        rng = np.random.default_rng(0)
        u = rng.uniform(0, 0.02, (n, scene.n_tendons)) if m else rng.uniform(0, 2.0, (n, scene.n_tendons))
        f = lambda: pj.solve_batch(scene, u, chunk_size=n, fallback=False, progress=False)
        jax.block_until_ready(f().q)
        ts = []
        for rep in range(5):
            t = time.perf_counter(); sol = f(); jax.block_until_ready(sol.q); ts.append(time.perf_counter()-t)
        out.append(f"{name} n={n} {np.median(ts)*1e3:.1f} ms st {np.mean(sol.steps):.2f} conv {np.mean(sol.converged):.2f}")
print(P.__file__.split('/')[2], " | ".join(out), flush=True)
