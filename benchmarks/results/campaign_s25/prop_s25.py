"""Rebuild a campaign draw that broke a property: python prop_s25.py RECORD_INDEX [RESULTS_JSON SEED]
(default: the seed-25 slice, benchmarks/results/campaign_deep_s25.json)."""
import json, sys
import os; ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "../../..")); sys.path.insert(0, ROOT + "/tests"); sys.path.insert(0, ROOT + "/benchmarks")
import numpy as np, jax, jax.numpy as jnp
import pacjax as pj
from scene_space import build, check, SAME_TIP, _tip, _newton_step, PropertyFailure
from campaign import structures_of
path, seed = (sys.argv[2], int(sys.argv[3])) if len(sys.argv) > 3 else (ROOT + "/benchmarks/results/campaign_deep_s25.json", 25)
d = json.load(open(path))
bad = d["not_ok"] if "not_ok" in d else [r for r in d["records"] if r["outcome"] != "ok"]
rec = bad[int(sys.argv[1])]
structure = structures_of(500, seed)[rec["structure_index"]]
print(structure.describe(), "|", rec["error"])
scene, controls = build(structure, rec["values"])
print("controls", controls, "conservative", scene.is_conservative)
single = pj.solve_equilibrium(scene, controls, fallback=False)
rows = np.stack([controls, 0.5 * controls])
batch = pj.solve_batch(scene, rows, fallback=False, progress=False)
first = jax.tree.map(lambda x: x[0], batch)
for name, e in (("single", single), ("batch0", first)):
    print(name, e.reason[:40], "steps", int(e.steps), "res", float(e.residual_norm), "eig", float(e.min_hessian_eigenvalue), "tip", _tip(scene, e.q))
for name, e in (("single", single), ("batch0", first)):
    c = jnp.asarray(controls, e.q.dtype)
    J = jax.jacfwd(scene.residual)(e.q, c)
    print(name, "cond J", float(jnp.linalg.cond(J)), "eig sym", np.linalg.eigvalsh(0.5*(J+J.T))[:3], "eig J", np.sort(np.linalg.eigvals(J).real)[:3])
    qn, _ = _newton_step(scene, controls, e.q)
    print("  newton step norm", float(jnp.linalg.norm(qn - e.q)), "tip moved", np.linalg.norm(_tip(scene, qn) - _tip(scene, e.q)))
for rows in (controls[None], np.stack([controls] * 2), np.stack([controls] * 5)):
    b = pj.solve_batch(scene, rows, fallback=False, progress=False)
    print("batch", rows.shape[0], np.asarray(b.steps), list(np.asarray(b.converged)), list(np.asarray(b.stable)), [np.round(_tip(scene, q), 5) for q in b.q[:2]])
try:
    print("check ->", check(scene, controls, structure.dtype))
except PropertyFailure as err:
    print("check -> PropertyFailure", err)
np.set_printoptions(precision=5, linewidth=150)
print("q single", np.asarray(single.q)); print("q batch0", np.asarray(first.q))
for name, e in (("single", single), ("batch0", first)):
    q = e.q
    c = jnp.asarray(controls, q.dtype)
    for k in range(4):
        q, _ = _newton_step(scene, controls, q)
    J = jax.jacfwd(scene.residual)(q, c)
    w, v = np.linalg.eigh(0.5 * (J + J.T))
    print(name, "after 4 Newton: |F|", float(jnp.linalg.norm(scene.residual(q, c))), "eig", w[:2], "q", np.asarray(q))
    print("   soft mode", v[:, 0])
