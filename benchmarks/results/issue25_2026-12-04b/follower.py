import sys
import numpy as np, jax.numpy as jnp
import pacjax as pj
from pacjax.cli.bench import random_commands
dt = None if sys.argv[1] == "default" else float(sys.argv[1])
rows = int(sys.argv[2]) if len(sys.argv) > 2 else 200
u = random_commands(rows, seed=1)
for name, scene in [
    ("PAC follower 3.41 N", pj.presets.stella2023(pj.PAC(), loads=(pj.PointForce((0.0, 0.0, 3.41), segment=2, s=1.0, follower=True),))),
    ("PAC tip moment (dead)", pj.presets.stella2023(pj.PAC(), loads=(pj.PointMoment((0.0, 0.05, 0.02), segment=2, s=1.0),))),
    ("PCC 200 g", pj.presets.stella2023(pj.PCC(), tip_mass=0.2)),
]:
    eq = pj.solve_batch(scene, u, options=pj.SolverOptions(initial_dt=dt), progress=False)
    s = np.asarray(eq.steps)
    print(f"dt={sys.argv[1]} {name:24s} conv {np.mean(eq.converged):.3f} stable {np.mean(eq.stable):.3f} steps {s.mean():.2f} max {s.max()}", flush=True)
