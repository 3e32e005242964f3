import os, sys, time, json, statistics
sys.path.insert(0, "/work/main/benchmarks")
import numpy as np, jax
import pacjax as pj
from bench_dynamics import _batch_commands
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
cmds = _batch_commands(64)
def batch():
    return pj.simulate_batch(scene, (0.0, 0.5), cmds, start.q, saveat=[0.5], damping=damping, rtol=1e-4, atol=1e-6, max_steps=200000)
walls = []
for k in range(3):
    t = time.perf_counter(); tr = batch(); jax.block_until_ready(tr); walls.append(time.perf_counter() - t)
tag = repr(os.environ.get("XLA_FLAGS", ""))

print(tag, pj.__file__.split("/")[2], json.dumps(dict(first=round(walls[0], 1), warm=[round(w, 2) for w in walls[1:]], aggregate_rtf=round(64*0.5/statistics.median(walls[1:]), 2), steps_sum=int(np.sum(tr.num_steps)), max_steps=int(np.max(tr.num_steps)), successful=int(np.sum(np.asarray(tr.successful))))), flush=True)
