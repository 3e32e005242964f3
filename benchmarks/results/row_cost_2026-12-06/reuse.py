import sys, time
import numpy as np, jax
import pacjax as pj
from pacjax._dynamics.simulate import rosenbrock23
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
STEP = np.array([0.04] + [0.0] * 8)
ts = np.linspace(0, 0.5, 11)
for r in (2, 3, 10, 40):
    tr = pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=ts, damping=damping, rtol=1e-4, solver=rosenbrock23(reuse=r))
    s, a = int(tr.num_steps), int(tr.num_accepted_steps)
    print(r, s, a, {c: 2*s + c*a/r for c in (24, 12, 6, 3)}, flush=True)
