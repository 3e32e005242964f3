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
low = S.integrate.lower(sc, damping, controls, q0, qdot0, span, ts, None, opts)
txt = low.as_text()
t = time.perf_counter(); low = S.integrate.lower(sc, damping, controls, q0, qdot0, span, ts, None, opts); tl = time.perf_counter() - t
txt = low.as_text()
t = time.perf_counter(); c0 = time.process_time(); comp = low.compile(); tc = time.perf_counter() - t; cpu = time.process_time() - c0
opt = comp.compiled.as_text()
print(f"lower {tl:.1f} s compile {tc:.1f} s (cpu {cpu:.1f} s) potrf/cholesky in optimised: {len(re.findall('potrf|cholesky', opt))} getrf {len(re.findall('getrf', opt))}", flush=True)
runs = []
for _ in range(5):
    t = time.perf_counter(); tr = comp(sc, damping, controls, q0, qdot0, span, ts, None, opts); jax.block_until_ready(tr); runs.append(time.perf_counter()-t)
print(f"warm median {np.median(runs):.3f} s, steps {int(tr.num_steps)}", flush=True)
