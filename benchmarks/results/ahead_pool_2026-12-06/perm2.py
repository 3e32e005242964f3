import sys, numpy as np, jax
import pacjax as pj
from pacjax.io import load_scene
import pacjax._statics.pool as P
P.CPU_LANES = 1
scene, _, _ = load_scene("/work/main/experiments/scenes/tendon_single.toml")
u = np.random.default_rng(0).uniform(0, 3.0, (64, scene.n_tendons))
a = pj.solve_batch(scene, u, chunk_size=64, progress=False)
for seed in range(2):
    perm = np.random.default_rng(seed).permutation(64)
    b = pj.solve_batch(scene, u[perm], chunk_size=64, progress=False)
    print("permuted rows differing:", np.any(np.asarray(a.q)[perm] != np.asarray(b.q), axis=1).sum())
