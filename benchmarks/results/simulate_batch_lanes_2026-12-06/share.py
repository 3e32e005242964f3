import sys, time
sys.path.insert(0, "benchmarks")
import numpy as np, jax
import pacjax as pj
from bench_dynamics import _batch_commands
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
cmds = _batch_commands(8)
kw = dict(saveat=[0.5], damping=damping, rtol=1e-4, atol=1e-6)
t = time.perf_counter(); s = pj.simulate(scene, (0, 0.5), cmds[3], start.q, **kw); jax.block_until_ready(s); print("simulate first", round(time.perf_counter()-t, 2))
t = time.perf_counter(); b = pj.simulate_batch(scene, (0, 0.5), cmds, start.q, **kw); jax.block_until_ready(b); print("batch first", round(time.perf_counter()-t, 2))
t = time.perf_counter(); b = pj.simulate_batch(scene, (0, 0.5), cmds, start.q, **kw); jax.block_until_ready(b); print("batch warm", round(time.perf_counter()-t, 2))
print("row 3 vs simulate", float(np.max(np.abs(np.asarray(b.q[3]) - np.asarray(s.q)))), int(b.num_steps[3]), int(s.num_steps))
