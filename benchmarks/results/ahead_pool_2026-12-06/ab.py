import time, sys, numpy as np, jax
import pacjax as pj
from pacjax._statics import pool as P
P.CPU_LANES = int(sys.argv[1]) if len(sys.argv) > 1 else 2
which = sys.argv[2].split(",") if len(sys.argv) > 2 else ["paper", "tentacle", "tentacle_poly1"]
out = []
scenes = {"paper": (lambda: pj.presets.stella2023(pj.PAC(), tip_mass=0.2), 0.02),
          "tentacle": (lambda: pj.presets.tentacle(), None),
          "tentacle_poly1": (lambda: pj.presets.tentacle(model=pj.PolynomialCurvature(1)), None)}
for name in which:
    mk, m = scenes[name]
    scene = mk()
    for n in (1000,):
        rng = np.random.default_rng(0)
        u = rng.uniform(0, 0.02, (n, scene.n_tendons)) if m else rng.uniform(0, 2.0, (n, scene.n_tendons))
        f = lambda: pj.solve_batch(scene, u, chunk_size=n, fallback=False, progress=False)
        t = time.perf_counter(); jax.block_until_ready(f().q); first = time.perf_counter() - t
        ts = []
        for rep in range(5):
            t = time.perf_counter(); sol = f(); jax.block_until_ready(sol.q); ts.append(time.perf_counter()-t)
        out.append(f"{name} n={n} {np.median(ts)*1e3:.1f} ms first {first:.1f}s st {np.mean(sol.steps):.2f}/{np.max(sol.steps)} conv {np.mean(sol.converged):.3f} stab {np.mean(sol.stable):.3f} res {np.max(sol.residual_norm):.1e}")
        np.save(f"/tmp/q_{name}_{P.__file__.split('/')[2]}.npy", np.asarray(sol.q))
print(P.__file__.split('/')[2], " | ".join(out), flush=True)
