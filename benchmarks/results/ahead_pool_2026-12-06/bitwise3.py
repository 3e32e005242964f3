import sys, numpy as np, jax
import pacjax as pj
from pacjax.io import load_scene
import pacjax._statics.pool as P
P.CPU_LANES = int(sys.argv[1])
scene, _, _ = load_scene("/work/main/experiments/scenes/tendon_single.toml")
rng = np.random.default_rng(0)
u = rng.uniform(0, 1, (640, scene.n_tendons)) * 3.0
a = pj.solve_batch(scene, u, chunk_size=64, progress=False)
res = {}
for start in (0, 64, 100, 192, 250, 300):
    b = pj.solve_batch(scene, u[start:], chunk_size=64, progress=False)
    d = np.any(np.asarray(a.q[start:]) != np.asarray(b.q), axis=1)
    print(P.CPU_LANES, start, "rows differing", d.sum(), np.nonzero(d)[0][:8] + start)
rows = np.nonzero(d)[0] + start
ahead_ended = [int(pj.solve_equilibrium(scene, u[r]).steps) - int(a.steps[r]) for r in rows[:10]]
print("single - batch steps for differing rows:", ahead_ended)
ok = np.nonzero(~d)[0][:10] + start
print("same for equal rows:", [int(pj.solve_equilibrium(scene, u[r]).steps) - int(a.steps[r]) for r in ok])
