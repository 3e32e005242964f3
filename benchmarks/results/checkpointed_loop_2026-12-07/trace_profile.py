"""Where integrate's tracing (lowering) time goes: cProfile of the lower call."""
import cProfile, pstats, time, io
import numpy as np, jax, jax.numpy as jnp
import pacjax as pj
from pacjax._dynamics import simulate as S
print(pj.__file__, flush=True)
STEP = np.array([0.04, 0, 0, 0, 0, 0, 0, 0, 0.0])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
dtype = jnp.float64
controls = S.check_simulation_controls(scene, STEP, 0.0, dtype)
q0 = S.check_q(scene, start.q, dtype); qdot0 = S.check_qdot(scene, None, dtype)
sc, damping, opts, span, ts = S.prepare(scene, 0.0, 0.5, np.linspace(0, .5, 11), damping, None, 1e-4, 1e-6, 100000, False, S.PHI_INERTIA_FACTOR, None)
pr = cProfile.Profile()
t = time.perf_counter(); pr.enable()
low = S.integrate.lower(sc, damping, controls, q0, qdot0, span, ts, None, opts)
pr.disable(); print("lower", round(time.perf_counter() - t, 2), flush=True)
s = io.StringIO(); pstats.Stats(pr, stream=s).sort_stats("cumulative").print_stats(60); print(s.getvalue())
s = io.StringIO(); pstats.Stats(pr, stream=s).sort_stats("tottime").print_stats(30); print(s.getvalue())
t = time.perf_counter(); comp = low.compile(); print("compile", round(time.perf_counter() - t, 2), flush=True)
