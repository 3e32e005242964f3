"""First call and warm call of a solve whose tip-mass site is traced (a jit argument), the
paper's robot with PAC: what the traced-site integration costs. PACJAX_CACHE_DIR=off."""
import time, json, sys
import equinox as eqx, jax, jax.numpy as jnp, numpy as np
import pacjax as pj

scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
mass = next(i for i, l in enumerate(scene.loads) if isinstance(l, pj.PointMass))
u = jnp.linspace(0.0, 0.02, scene.n_tendons)  # bent: no symmetry

@eqx.filter_jit
def tip(s, u):
    sc = eqx.tree_at(lambda x: x.loads[mass].s, scene, s)
    eq = pj.solve_equilibrium(sc, u, fallback=False)
    return pj.tip_pose(sc, eq.q)[0], eq.steps

t0 = time.perf_counter(); out = jax.block_until_ready(tip(jnp.asarray(0.9), u)); first = time.perf_counter() - t0
warm = []
for s in (0.8, 0.7, 0.6):
    t0 = time.perf_counter(); jax.block_until_ready(tip(jnp.asarray(s), u)); warm.append(time.perf_counter() - t0)
print(json.dumps({"first_s": first, "warm_s": float(np.median(warm)), "tip": np.asarray(out[0]).tolist(), "steps": int(out[1])}))
