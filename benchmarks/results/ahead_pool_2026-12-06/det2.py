import numpy as np, jax
import pacjax as pj
for name, scene, hi in [("paper", pj.presets.stella2023(pj.PAC(), tip_mass=0.2), 0.02),
                        ("tentacle", pj.presets.tentacle(), 2.0),
                        ("poly1", pj.presets.tentacle(model=pj.PolynomialCurvature(1)), 2.0)]:
    u = np.random.default_rng(0).uniform(0, hi, (600, scene.n_tendons))
    a = pj.solve_batch(scene, u, chunk_size=64, progress=False)
    perm = np.random.default_rng(1).permutation(600)
    b = pj.solve_batch(scene, u[perm], chunk_size=64, progress=False)
    c = pj.solve_batch(scene, u[100:], chunk_size=64, progress=False)
    print(name, "permuted rows differing", np.any(np.asarray(a.q)[perm] != np.asarray(b.q), axis=1).sum(),
          "offset rows differing", np.any(np.asarray(a.q)[100:] != np.asarray(c.q), axis=1).sum(),
          "residual/energy differing", np.sum(np.asarray(a.residual_norm)[perm] != np.asarray(b.residual_norm)), np.sum(np.asarray(a.energy)[perm] != np.asarray(b.energy)),
          "steps", float(np.mean(a.steps)))
