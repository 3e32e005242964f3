import sys, time, json, statistics, os
sys.path.insert(0, "benchmarks")
import numpy as np, jax
import pacjax as pj
from pacjax._dynamics.simulate import rosenbrock23
from bench_dynamics import _batch_commands
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
B = int(sys.argv[1]); G = int(sys.argv[2]); reps = int(sys.argv[3]) if len(sys.argv) > 3 else 2
cmds = _batch_commands(64)[:B]
kw = {} if G == 1 else dict(rows_at_once=G, solver=rosenbrock23(os.environ.get("JAC", "exact")))
def batch():
    return pj.simulate_batch(scene, (0.0, 0.5), cmds, start.q, saveat=[0.5], damping=damping, rtol=1e-4, atol=1e-6, max_steps=200000, **kw)
walls = []
for k in range(reps):
    t = time.perf_counter(); tr = batch(); jax.block_until_ready(tr); walls.append(time.perf_counter() - t)
print(json.dumps(dict(B=B, G=G, first=round(walls[0],2), warm=[round(w,2) for w in walls[1:]], per_row=round(statistics.median(walls[1:])/B,4), steps_sum=int(np.sum(tr.num_steps)), max_steps=int(np.max(tr.num_steps)), steps=[int(x) for x in tr.num_steps], successful=int(np.sum(np.asarray(tr.successful))), tip=[float(x) for x in np.asarray(tr.q)[:,-1,:3].sum(0)])))
