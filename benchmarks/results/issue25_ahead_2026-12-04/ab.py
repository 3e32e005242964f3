"""Warm solve_batch rate: paper PAC (bench scene), tentacle PAC; and vs_soromox (a) Poly1. Prints medians."""
import os, sys, time
import numpy as np, jax
import pacjax as pj
n = int(os.environ.get("N", "1000")); reps = int(os.environ.get("REPS", "5"))
tag = sys.argv[1]
cases = {
  "paper PAC": (pj.presets.stella2023(pj.PAC(), tip_mass=0.2), 0.02),
  "tentacle PAC": (pj.presets.tentacle(pj.PAC()), 8.0),
  "tentacle Poly1": (pj.presets.tentacle(pj.PolynomialCurvature(1)), 8.0),
}
for name in os.environ.get("CASES", "paper PAC,tentacle PAC,tentacle Poly1").split(","):
    sc, hi = cases[name]
    U = np.random.default_rng(0).uniform(0, hi, (n, sc.n_tendons))
    call = lambda: pj.solve_batch(sc, U, fallback=False, progress=False)
    eq = call(); jax.block_until_ready(eq.q)
    t = []
    for _ in range(reps):
        t0 = time.perf_counter(); e = call(); jax.block_until_ready(e.q); t.append(time.perf_counter() - t0)
    m = np.median(t)
    print(f"{tag} {name} n={n}: {m*1e3:.1f} ms {n/m:.0f} eq/s steps {np.mean(e.steps):.3f}/{np.max(e.steps)} conv {np.mean(e.converged):.4f} res {np.max(e.residual_norm):.1e} stable {np.mean(e.stable):.4f}", flush=True)
