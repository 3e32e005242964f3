import sys, numpy as np, jax, jax.numpy as jnp
sys.path.insert(0, "/work/main/benchmarks")
import vs_soromox as vs
key = sys.argv[1] if len(sys.argv) > 1 else "a"
n = int(sys.argv[2]) if len(sys.argv) > 2 else 1000
prob = vs.PROBLEMS[key]
rows = prob.rows(n)
robot = vs.soromox_robot(prob, 8)
sm = vs.soromox_solver(prob, 1e-10, 200)
tips, conv, steps, res, sres = [np.asarray(x) for x in sm(robot, jnp.asarray(rows))]
print("soromox steps", steps.mean(), np.bincount(steps))
for model in ("PAC", "Poly1"):
    scene = vs.pacjax_scene(prob, vs.MODELS[model]())
    eq = vs.pacjax_batch(prob, scene, rows)
    s = np.asarray(eq.steps)
    d = s - steps
    print(model, "steps", s.mean(), np.bincount(s), "diff hist", {int(k): int((d == k).sum()) for k in np.unique(d)})
    np.save(f"/work/notes/s16/steps_{key}_{model}.npy", np.stack([s, steps]))
