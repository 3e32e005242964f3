import logging, time, sys
import numpy as np, jax
jax.config.update("jax_log_compiles", True)
import pacjax as pj
print(pj.__file__, flush=True)
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
print("---- simulate", flush=True)
t = time.perf_counter()
tr = pj.simulate(scene, (0.0, 0.5), np.array([0.04] + [0.0] * 8), q0=start.q, saveat=np.linspace(0, 0.5, 11), damping=damping, rtol=1e-4)
jax.block_until_ready(tr); print("first", round(time.perf_counter() - t, 2), flush=True)
