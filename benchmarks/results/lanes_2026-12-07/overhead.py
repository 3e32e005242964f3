"""Warm cost of one batch row's parts on one core: the start's alignment call, integrate's call
(dispatch and run), and the dispatch alone (an integrate of a zero-length span)."""
import sys, time, statistics, cProfile, pstats, io
sys.path.insert(0, "/work/main/benchmarks")
import numpy as np, jax, jax.numpy as jnp
import pacjax as pj
from pacjax._dynamics import simulate as S
from bench_dynamics import _batch_commands
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
u = jnp.asarray(_batch_commands(64)[0])
sc, dmp, opts, span, ts = S.prepare(scene, 0.0, 0.5, [0.5], damping, None, 1e-4, 1e-6, 100000, False, S.PHI_INERTIA_FACTOR, None)
q = S.check_q(scene, start.q, jnp.float64); v = S.check_qdot(scene, None, jnp.float64)
dt0 = S.check_dt0(None, 0.0, 0.5, jnp.float64)
def align(): return jax.block_until_ready(S.aligned_rest_start(sc, dmp if False else sc and damping and u, q, v, span[0])) if False else jax.block_until_ready(S.aligned_rest_start(sc, u, q, v, span[0]))
q1 = align()
def integ(): return jax.block_until_ready(S.integrate(sc, dmp, u, q1, v, span, ts, dt0, opts))
integ()
for name, f in (("align", align), ("integrate", integ)):
    w = []
    for _ in range(7):
        t = time.perf_counter(); f(); w.append(time.perf_counter() - t)
    print(name, f"median {statistics.median(w)*1e3:.1f} ms, min {min(w)*1e3:.1f}", flush=True)
pr = cProfile.Profile(); pr.enable(); integ(); align(); pr.disable()
s = io.StringIO(); pstats.Stats(pr, stream=s).sort_stats("tottime").print_stats(12); print(s.getvalue()[:3000])
