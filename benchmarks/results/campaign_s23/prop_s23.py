"""Rebuild a campaign draw: python prop_s23.py RECORD_INDEX"""
import json, sys
import os; ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "../../..")); sys.path.insert(0, ROOT + "/tests"); sys.path.insert(0, ROOT + "/benchmarks")
import numpy as np, jax, jax.numpy as jnp
import pacjax as pj
from scene_space import build, check, SAME_TIP, _tip, _newton_step
from campaign import structures_of
d = json.load(open(ROOT + "/benchmarks/results/campaign_deep_s23.json"))
bad = d["not_ok"]
rec = bad[int(sys.argv[1])]
k = rec["structure_index"]
structure = structures_of(500, 23)[k]
print(structure.describe(), rec["error"])
scene, controls = build(structure, rec["values"])
print("controls", controls, "dtype", structure.dtype)
single = pj.solve_equilibrium(scene, controls, fallback=False)
rows = np.stack([controls, 0.5 * controls])
batch = pj.solve_batch(scene, rows, fallback=False, progress=False)
first = jax.tree.map(lambda x: x[0], batch)
for name, e in (("single", single), ("batch0", first)):
    print(name, e.reason, "steps", int(e.steps), "res", float(e.residual_norm), "eig", float(e.min_hessian_eigenvalue), "energy", float(e.energy), "tip", _tip(scene, e.q))
print("gap", np.linalg.norm(_tip(scene, first.q) - _tip(scene, single.q)), "allowed", SAME_TIP[structure.dtype] * float(scene.robot.total_length))
for name, e in (("single", single), ("batch0", first)):
    J = jax.jacfwd(scene.residual)(e.q, jnp.asarray(controls, e.q.dtype))
    F = scene.residual(e.q, jnp.asarray(controls, e.q.dtype))
    print(name, "|F|", float(jnp.linalg.norm(F)), "cond J", float(jnp.linalg.cond(J)), "eig sym", np.linalg.eigvalsh(0.5*(J+J.T))[:3])
    qn = _newton_step(scene, controls, e.q)
    print("  newton step norm", float(jnp.linalg.norm(qn - e.q)), "tip moved", np.linalg.norm(_tip(scene, qn) - _tip(scene, e.q)))
