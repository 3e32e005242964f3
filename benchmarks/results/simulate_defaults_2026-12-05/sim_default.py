import time, sys, os
import numpy as np, jax
import pacjax as pj
STEP = np.array([0.04, 0, 0, 0, 0, 0, 0, 0, 0.0])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
kw = {} if sys.argv[1] == "default" else dict(rtol=float(sys.argv[1]), atol=float(sys.argv[1]) * 1e-2)
dur = float(sys.argv[2])
eq = pj.solve_equilibrium(scene, np.zeros(9))
q0 = None if sys.argv[3] == "straight" else eq.q
for i in range(2):
    t = time.perf_counter()
    tr = pj.simulate(scene, (0.0, dur), STEP, q0=q0, **kw); jax.block_until_ready(tr)
    tip = np.asarray(pj.tip_pose(scene, tr.q[-1])[0])
    print(sys.argv[1:], "call", i, round(time.perf_counter() - t, 2), "s", int(tr.num_steps), bool(tr.successful), tip, flush=True)
