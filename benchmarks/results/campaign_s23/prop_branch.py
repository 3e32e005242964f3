import json, sys
import os; ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "../../..")); sys.path.insert(0, ROOT + "/tests"); sys.path.insert(0, ROOT + "/benchmarks")
import numpy as np, jax
import pacjax as pj
from scene_space import build, _tip
from campaign import structures_of
d = json.load(open(ROOT + "/benchmarks/results/campaign_deep_s23.json"))
bad = d["not_ok"]
rec = bad[2]
structure = structures_of(500, 23)[rec["structure_index"]]
scene, controls = build(structure, rec["values"])
print(scene.is_conservative, [type(l).__name__ + (" follower" if getattr(l, "follower", False) else "") for l in scene.loads])
single = pj.solve_equilibrium(scene, controls, fallback=False)
print("single", int(single.steps), _tip(scene, single.q))
for rows in (controls[None], np.stack([controls] * 2), np.stack([controls] * 5)):
    b = pj.solve_batch(scene, rows, fallback=False, progress=False)
    print("batch", rows.shape[0], np.asarray(b.steps), [np.round(_tip(scene, q), 5) for q in b.q[:2]])
