import sys, time
import numpy as np, jax
import pacjax as pj
from pacjax._dynamics.simulate import rosenbrock23
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
STEP = np.array([0.04] + [0.0] * 8)
ts = np.linspace(0, 0.5, 201)
for name, solver in [("reuse20", rosenbrock23()), ("reuse1", rosenbrock23(reuse=1)), ("reuse5", rosenbrock23(reuse=5))]:
    t = time.perf_counter()
    tr = pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=ts, damping=damping, rtol=1e-4, solver=solver)
    jax.block_until_ready(tr)
    print(name, int(tr.num_steps), int(tr.num_accepted_steps), round(time.perf_counter() - t, 1), flush=True)
    if name == "reuse20":
        np.save("traj.npy", np.asarray(tr.q))
