import time, sys
import numpy as np, jax, jax.numpy as jnp, equinox as eqx
import pacjax as pj
from pacjax._dynamics import simulate as S
print(pj.__file__, flush=True)
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
dtype = jnp.float64
controls = S.check_simulation_controls(scene, np.array([0.04] + [0.0] * 8), 0.0, dtype)
q0 = S.check_q(scene, start.q, dtype); qdot0 = S.check_qdot(scene, None, dtype)
sc, damping, opts, span, ts = S.prepare(scene, 0.0, 0.5, np.linspace(0, .5, 11), damping, None, 1e-4, 1e-6, 100000, False, S.PHI_INERTIA_FACTOR, None)
fn = S.aligned_rest_start.__wrapped__
for opt in sys.argv[1:]:
    o = {"xla_cpu_use_fusion_emitters": False}
    if opt == "O0": o["xla_backend_optimization_level"] = 0
    if opt == "fusion": o = {}
    j = eqx.filter_jit(fn, compiler_options=o) if o else eqx.filter_jit(fn)
    t = time.perf_counter(); low = j.lower(sc, controls, q0, qdot0, span[0]); tl = time.perf_counter() - t
    t = time.perf_counter(); c = low.compile(); tc = time.perf_counter() - t
    t = time.perf_counter(); out = jax.block_until_ready(c(sc, controls, q0, qdot0, span[0])); tr = time.perf_counter() - t
    print(opt, "lower", round(tl, 2), "compile", round(tc, 2), "run", round(tr * 1e3, 2), "ms", np.asarray(out)[:8], flush=True)
