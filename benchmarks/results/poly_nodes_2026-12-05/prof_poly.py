"""Per-row cost of the linearisation pieces, problem (a)/(b), PAC vs Poly1."""
import sys, time
sys.path.insert(0, "/work/main/benchmarks")
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
import vs_soromox as vs
import pacjax as pj
from pacjax._model import hessian as H

prob = vs.PROBLEMS[sys.argv[1] if len(sys.argv) > 1 else "a"]
B = 128
def bench(f, *a, n=20):
    jax.block_until_ready(f(*a))
    ts = []
    for _ in range(n):
        t = time.perf_counter(); jax.block_until_ready(f(*a)); ts.append(time.perf_counter() - t)
    return np.median(ts) / B * 1e6
for name in sys.argv[2:] or ["PAC", "Poly1"]:
    scene = vs.pacjax_scene(prob, vs.MODELS[name]())
    rng = np.random.default_rng(0)
    nq = scene.n_dofs if hasattr(scene, "n_dofs") else None
    eq = pj.solve_batch(scene, prob.rows(B) if prob.tendons else np.zeros((B, 0)), fallback=False, progress=False) if prob.tendons else None
    if eq is None:
        continue
    q = jnp.asarray(eq.q); ctrl = jnp.asarray(prob.rows(B))
    consts = scene.constants(jnp.float64)
    f = jax.jit(jax.vmap(lambda x, c: H.energy_derivatives(scene, x, c, consts)))
    t_all = bench(f, q, ctrl)
    plan = scene.energy_plan()
    def lin(x):
        coords = scene.coordinates(x)
        l = H._linearise(scene, coords, plan, consts, x.dtype)
        return l.values, l.jacobians
    t_lin = bench(jax.jit(jax.vmap(lin)), q)
    def curv(x):
        coords = scene.coordinates(x)
        *fi, ch, chan = scene.segment_inputs(plan, consts, x.dtype)
        vals = jax.vmap(scene._segment_frames)(coords, *fi)
        lam = jax.tree_util.tree_map(lambda v: jnp.ones_like(v) * 0.1, vals)
        return jax.vmap(scene.segment_frames_curvature)(coords, lam, *fi)
    t_curv = bench(jax.jit(jax.vmap(curv)), q)
    print(f"{name}: q {q.shape} all {t_all:.1f} us/row, linearise {t_lin:.1f}, frames curvature {t_curv:.1f}", flush=True)
