"""How far the batch's final tips moved between old and new (b2_old.npy, b2_new.npy)."""
import numpy as np, jax
import pacjax as pj
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
tip = jax.jit(jax.vmap(lambda q: pj.tip_pose(scene, q)[0]))
a, b = (np.asarray(tip(np.load(f"b2_{t}.npy"))) for t in ("old", "new"))
d = np.linalg.norm(a - b, axis=1) * 1e3
print(f"final tips moved, mm: max {d.max():.4f}, median {np.median(d):.4f}, rows above 0.01 mm {int((d > 0.01).sum())}")
