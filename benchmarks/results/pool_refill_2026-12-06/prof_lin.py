import time, numpy as np, jax, jax.numpy as jnp, equinox as eqx
import pacjax as pj
from pacjax._statics.problem import ScaledProblem
base = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
n = 128
rng = np.random.default_rng(0)
def variant(name, scene):
    m = scene.n_tendons
    u = jnp.asarray(rng.uniform(0, 0.02, (n, m))) if m else jnp.zeros((n, 0))
    q = jnp.asarray(rng.normal(0, 1, (n, scene.n_dofs))) * 0.5
    @jax.jit
    def lin(u, q):
        return jax.vmap(lambda uu, qq: ScaledProblem.build(scene, uu).linearise(qq))(u, q)
    jax.block_until_ready(lin(u, q))
    ts = []
    for _ in range(20):
        t0 = time.perf_counter(); jax.block_until_ready(lin(u, q)); ts.append(time.perf_counter() - t0)
    print(f"{name:30s} {np.median(ts)/n*1e6:6.1f} us/row")
variant("full", base)
variant("no tendons", pj.Scene(base.robot, base.models if base.segment_models else base.models[0], (), base.loads, base.markers, base.quadrature_points, base.rotation_substeps))
variant("no loads", pj.Scene(base.robot, base.models if base.segment_models else base.models[0], base.tendons, (), base.markers, base.quadrature_points, base.rotation_substeps))
variant("gravity only", pj.Scene(base.robot, base.models if base.segment_models else base.models[0], base.tendons, base.loads[:1], base.markers, base.quadrature_points, base.rotation_substeps))
variant("nothing", pj.Scene(base.robot, base.models if base.segment_models else base.models[0], (), (), base.markers, base.quadrature_points, base.rotation_substeps))
print(base.quadrature_points, base.rotation_substeps, len(base.tendons))
