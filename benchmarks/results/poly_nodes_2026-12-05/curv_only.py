import sys, time, os
sys.path.insert(0, "/work/main/benchmarks")
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
import vs_soromox as vs
import pacjax as pj
prob = vs.PROBLEMS["a"]; B = int(os.environ.get("B", 128))
scene = vs.pacjax_scene(prob, pj.PolynomialCurvature(1))
eq = pj.solve_batch(scene, prob.rows(B), fallback=False, progress=False)
q = jnp.asarray(eq.q); consts = scene.constants(jnp.float64); plan = scene.energy_plan()
print("knots", plan.knots.s)
mode = os.environ.get("MODE", "hess")
def curv(x):
    coords = scene.coordinates(x)
    *fi, ch, chan = scene.segment_inputs(plan, consts, x.dtype)
    vals = jax.vmap(scene._segment_frames)(coords, *fi)
    lam = jax.tree_util.tree_map(lambda v: jnp.ones_like(v) * 0.1, vals)
    from pacjax._model.kinematics import contract
    def f(qi, lm, *a):
        return contract(lm, scene._segment_frames(qi, *a))
    def frot(qi, lm, *a):
        r = scene._segment_frames(qi, *a)
        return jnp.sum(lm[0] * r[0])
    def fpos(qi, lm, *a):
        r = scene._segment_frames(qi, *a)
        return jnp.sum(lm[1] * r[1]) + jnp.sum(lm[2] * r[2])
    if mode == "fwdrot":
        return jax.vmap(jax.jacfwd(frot))(coords, lam, *fi)
    if mode == "fwdpos":
        return jax.vmap(jax.jacfwd(fpos))(coords, lam, *fi)
    if mode == "hessrot":
        return jax.vmap(jax.hessian(frot))(coords, lam, *fi)
    if mode == "hesspos":
        return jax.vmap(jax.hessian(fpos))(coords, lam, *fi)
    if mode == "revfwd":
        return jax.vmap(jax.jacrev(jax.jacfwd(f)))(coords, lam, *fi)
    if mode == "fwdfwd":
        return jax.vmap(jax.jacfwd(jax.jacfwd(f)))(coords, lam, *fi)
    if mode == "hess":
        return jax.vmap(jax.hessian(f))(coords, lam, *fi)
    if mode == "grad":
        return jax.vmap(jax.grad(f))(coords, lam, *fi)
    if mode == "val":
        return jax.vmap(f)(coords, lam, *fi)
    if mode == "fwd":
        return jax.vmap(jax.jacfwd(f))(coords, lam, *fi)
g = jax.jit(jax.vmap(curv))
jax.block_until_ready(g(q))
ts = []
for _ in range(int(os.environ.get("N", 30))):
    t = time.perf_counter(); jax.block_until_ready(g(q)); ts.append(time.perf_counter() - t)
print(mode, f"{np.median(ts)/B*1e6:.1f} us/row")
import collections, re
txt = g.lower(q).compile().as_text()
ops = collections.Counter(re.findall(r"= \w+\[[^\]]*\][^ ]* (\w+)\(", txt))
print(sum(ops.values()), ops.most_common(25))
fus = re.findall(r"fusion\(", txt)
print("fusions", len(fus))
open(f"/work/notes/s22/hlo_{mode}.txt","w").write(txt)
