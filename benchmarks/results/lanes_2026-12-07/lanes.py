"""simulate_batch of 64 step commands (PAC, 0.5 s, rtol 1e-4) with 1 to 4 rows side by side
(pacjax._statics.pool.CPU_LANES patched), warm, alternated, in one process."""
import os, sys, time, statistics
sys.path.insert(0, "/work/main/benchmarks")
import numpy as np, jax
import pacjax as pj
from pacjax._statics import pool
from pacjax._dynamics import batch as B
from bench_dynamics import _batch_commands
print(pj.__file__, "cores", len(os.sched_getaffinity(0)), flush=True)
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
cmds = _batch_commands(64)
def batch():
    return pj.simulate_batch(scene, (0.0, 0.5), cmds, start.q, saveat=[0.5], damping=damping, rtol=1e-4)
jax.block_until_ready(batch())
times = {k: [] for k in (1, 2, 3, 4)}
for r in range(2):
    for k in (1, 2, 3, 4):
        B.CPU_LANES = k
        t = time.perf_counter(); jax.block_until_ready(batch()); times[k].append(time.perf_counter() - t)
        print(k, round(times[k][-1], 2), flush=True)
for k, v in times.items():
    print(f"lanes {k}: {[round(x, 2) for x in v]} median {statistics.median(v):.2f} s, aggregate RTF {64 * 0.5 / statistics.median(v):.2f}")
