import re, sys, time
import numpy as np, jax, jax.numpy as jnp
import pacjax as pj
from pacjax._dynamics import simulate as S
STEP = np.array([0.04, 0, 0, 0, 0, 0, 0, 0, 0.0])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
dtype = jnp.float64
controls = S.check_simulation_controls(scene, STEP, 0.0, dtype)
q0 = S.check_q(scene, start.q, dtype); qdot0 = S.check_qdot(scene, None, dtype)
sc, damping, opts, span, ts = S.prepare(scene, 0.0, 0.5, np.linspace(0, .5, 11), damping, None, 1e-4, 1e-6, 100000, False, S.PHI_INERTIA_FACTOR, None)
import cProfile, pstats
from pacjax._dynamics import equations as E
calls = {"n": 0}
orig = S.vector_field
def counted(*a, **k):
    calls["n"] += 1
    return orig(*a, **k)
S.vector_field = counted
t = time.perf_counter()
pass
low = S.integrate.lower(sc, damping, controls, q0, qdot0, span, ts, None, opts)
pass
print("lower", time.perf_counter() - t, "vector_field calls", calls["n"])

t = time.perf_counter(); comp = low.compile(); print("compile", time.perf_counter() - t)
runs = []
for _ in range(3):
    t = time.perf_counter(); tr = comp(sc, damping, controls, q0, qdot0, span, ts, None, opts); jax.block_until_ready(tr); runs.append(time.perf_counter()-t)
print("warm", np.median(runs), int(tr.num_steps))
