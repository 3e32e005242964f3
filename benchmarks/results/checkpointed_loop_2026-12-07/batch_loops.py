"""The batch of 64 with the step loop as a scan and as the checkpointed while loop, in one
process (the new code; the loop forced through simulate's step_loop), warm runs alternated."""
import os, sys, time, json, statistics
sys.path.insert(0, "/work/main/benchmarks")
import numpy as np, jax
import pacjax as pj
from pacjax._dynamics import simulate as S
from bench_dynamics import _batch_commands
print(pj.__file__, flush=True)
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
cmds = _batch_commands(64)
def batch(loop):
    S.step_loop = lambda adjoint: loop
    tr = pj.simulate_batch(scene, (0.0, 0.5), cmds, start.q, saveat=[0.5], damping=damping, rtol=1e-4, atol=1e-6, max_steps=200000)
    jax.block_until_ready(tr)
    return tr
for loop in ("scan", "checkpointed"):
    t = time.perf_counter(); tr = batch(loop); print(loop, "first", round(time.perf_counter() - t, 1), "steps", int(np.sum(tr.num_steps)), flush=True)
walls = {"scan": [], "checkpointed": []}
for rnd in range(3):
    for loop in ("scan", "checkpointed") if rnd % 2 == 0 else ("checkpointed", "scan"):
        t = time.perf_counter(); batch(loop); walls[loop].append(round(time.perf_counter() - t, 2))
        print(rnd, loop, walls[loop][-1], flush=True)
print(json.dumps({k: dict(warm=v, median=statistics.median(v)) for k, v in walls.items()}), flush=True)
