"""Warm solve_batch of vs_soromox problem rows, one model: median of repeats."""
import sys, time, json
sys.path.insert(0, "/work/main/benchmarks")
import jax, numpy as np
import vs_soromox as vs
import pacjax as pj
prob = vs.PROBLEMS[sys.argv[1]]; model = sys.argv[2]; n = int(sys.argv[3])
scene = vs.pacjax_scene(prob, vs.MODELS[model]())
rows = prob.rows(n)
t0 = time.perf_counter(); eq = vs.pacjax_batch(prob, scene, rows); jax.block_until_ready(eq.q); first = time.perf_counter() - t0
ts = []
for _ in range(5):
    t = time.perf_counter(); eq = vs.pacjax_batch(prob, scene, rows); jax.block_until_ready(eq.q); ts.append(time.perf_counter() - t)
w = np.median(ts)
print(json.dumps(dict(src=pj.__file__, prob=prob.name, model=model, n=n, first=round(first, 2), warm=round(w, 4), eqps=round(n / w), steps=float(np.mean(eq.steps)), conv=float(np.mean(eq.converged)), tip0=np.asarray(vs.pacjax_tips(scene, eq.q))[0].tolist())))
