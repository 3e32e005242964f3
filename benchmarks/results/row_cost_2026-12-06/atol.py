import sys, time
import numpy as np, jax
import pacjax as pj
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
STEP = np.array([0.04] + [0.0] * 8)
ts = np.linspace(0, 0.5, 11)
ref = np.load("ref_tips.npy")
def tips(tr):
    return np.stack([np.asarray(pj.tip_pose(scene, q)[0]) for q in np.asarray(tr.q)])
for atol in (1e-6, 1e-5, 1e-4, 1e-3):
    tr = pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=ts, damping=damping, rtol=1e-4, atol=atol)
    err = np.max(np.linalg.norm(tips(tr) - ref, axis=1)) * 1e3
    print(atol, int(tr.num_steps), int(tr.num_accepted_steps), round(err, 4), flush=True)
print("q scale", np.abs(np.asarray(start.q)).round(4))
