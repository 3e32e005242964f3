import time, json, statistics, os, sys
import numpy as np, jax
import pacjax as pj
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
STEP = np.array([0.04] + [0.0] * 8)
ts = np.linspace(0, 0.5, 11)
def run(rtol=1e-4):
    return pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=ts, damping=damping, rtol=rtol)
def tips(tr):
    return np.stack([np.asarray(pj.tip_pose(scene, q)[0]) for q in np.asarray(tr.q)])
ref_path = "ref_tips.npy"
if not os.path.exists(ref_path):
    ref = run(1e-7); np.save(ref_path, tips(ref)); print("ref steps", int(ref.num_steps))
ref = np.load(ref_path)
walls = []
for k in range(7):
    t = time.perf_counter(); tr = run(); jax.block_until_ready(tr); walls.append(time.perf_counter() - t)
err = np.max(np.linalg.norm(tips(tr) - ref, axis=1)) * 1e3
print(os.environ.get("TAG"), pj.__file__.split("/")[2], json.dumps(dict(first=round(walls[0],2), warm=round(statistics.median(walls[1:]),3), steps=int(tr.num_steps), acc=int(tr.num_accepted_steps), err_mm=float(err))), flush=True)
