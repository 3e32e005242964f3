import time, sys, jax, numpy as np
import pacjax as pj
STEP = np.array([0.04, 0, 0, 0, 0, 0, 0, 0, 0.0])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(9))
damping = pj.Damping.modal(scene)
f = lambda: pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=np.linspace(0, 0.5, 11), damping=damping)
t = time.perf_counter(); tr = f(); jax.block_until_ready(tr.q); c = time.perf_counter() - t
ts = []
for _ in range(5):
    t = time.perf_counter(); tr = f(); jax.block_until_ready(tr.q); ts.append(time.perf_counter() - t)
print(f"first {c:.2f} s warm {np.median(ts):.3f} (min {min(ts):.3f}) steps {int(tr.num_steps)} acc {int(tr.num_accepted_steps)} us/step {np.median(ts)/int(tr.num_steps)*1e6:.0f}")
print("tip", np.asarray(pj.tip_pose(scene, np.asarray(tr.q)[-1])[0]))
