import os, glob, gzip, json, collections, time
import numpy as np, jax
import pacjax as pj
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
STEP = np.array([0.04] + [0.0] * 8)
def run():
    return pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=[0.5], damping=damping)
jax.block_until_ready(run()); jax.block_until_ready(run())
d = "/tmp/prof_sim"; os.system(f"rm -rf {d}")
with jax.profiler.trace(d, create_perfetto_trace=True):
    tr = run(); jax.block_until_ready(tr)
print("steps", int(tr.num_steps))
