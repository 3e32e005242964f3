import numpy as np, jax, os, sys
import pacjax as pj
STEP = np.array([0.04,0,0,0,0,0,0,0,0.])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(9))
damping = pj.Damping.modal(scene)
sv = np.linspace(0, 0.5, 11)
ref = pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=sv, damping=damping, rtol=1e-8, atol=1e-10, solver=pj.dynamics.rosenbrock23())
tip = lambda t: np.stack([np.asarray(pj.tip_pose(scene, q)[0]) for q in np.asarray(t.q)])
for rtol in [float(x) for x in sys.argv[1:]]:
    tr = pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=sv, damping=damping, rtol=rtol, atol=rtol*1e-2)
    print("filter", os.environ.get("PJ_FILTER"), "rtol", rtol, "steps", int(tr.num_steps), "acc", int(tr.num_accepted_steps), "tip err mm %.4f" % (1e3*np.abs(tip(tr)-tip(ref)).max()), flush=True)
