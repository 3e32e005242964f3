# Tip position (static frames at given q) on a coarser knot grid against a fine one.
import os, sys, json
import numpy as np
import pacjax._model.kinematics as K
K._MIN_INTERVALS = int(sys.argv[1]); K._INTERVAL_NODES = int(sys.argv[2]); QP = int(sys.argv[3])
import pacjax as pj, jax.numpy as jnp
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2, quadrature_points=QP)
qs = np.load("qs.npy")
out = []
for q in qs:
    r, p = scene.frames(jnp.asarray(q), np.array([0, 1, 2]), np.array([1.0, 1.0, 1.0]))
    out.append(np.asarray(p))
np.save(f"tips_{sys.argv[1]}_{sys.argv[2]}_{QP}.npy", np.array(out))
