import time, json, statistics
import numpy as np, jax
import pacjax as pj
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
STEP = np.array([0.04] + [0.0] * 8)
def run():
    return pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=np.linspace(0, 0.5, 11), damping=damping)
walls = []
for k in range(8):
    t = time.perf_counter(); tr = run(); jax.block_until_ready(tr); walls.append(time.perf_counter() - t)
print(json.dumps(dict(first=walls[0], median_warm=statistics.median(walls[1:]), min_warm=min(walls[1:]), steps=int(tr.num_steps), tip=[float(x) for x in np.asarray(pj.tip_pose(scene, tr.q[-1])[0])])))
