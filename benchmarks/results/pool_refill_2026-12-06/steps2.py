import numpy as np, jax, time, sys
import pacjax as pj
STEP = np.array([0.04,0,0,0,0,0,0,0,0.])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
for label, solver in [("exact reuse1", pj.dynamics.rosenbrock23("exact", reuse=1)), ("exact reuse5", pj.dynamics.rosenbrock23("exact", reuse=5)), ("exact reuse20 nosecant", __import__("dataclasses").replace(pj.dynamics.rosenbrock23("exact"), secant=False)), ("stiff", pj.dynamics.rosenbrock23("stiff"))]:
    tr = pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=np.linspace(0,0.5,11), damping=damping, solver=solver, dense=True)
    ts = np.asarray(tr.solution.interpolation.ts); ts = ts[np.isfinite(ts)]
    h = np.diff(ts)
    print(label, "steps", int(tr.num_steps), "accepted", int(tr.num_accepted_steps))
    print("   ", [ (a, int(((ts[:-1]>=a)&(ts[:-1]<b)).sum()), float("%.2g"%np.median(h[(ts[:-1]>=a)&(ts[:-1]<b)]))) for a,b in [(0,0.01),(0.01,0.1),(0.1,0.2),(0.2,0.3),(0.3,0.4),(0.4,0.5)]])
