"""First call of a single solve whose first attempt fails (a campaign draw: Poly2+Poly1, a dead
moment, load continuation), fresh process, cache off."""
import time, sys, json, collections, pickle
sys.path.insert(0, "/work/main/tests")
import jax
ev = collections.Counter()
jax.monitoring.register_event_duration_secs_listener(lambda e, d, **k: ev.update({e.split('/')[-1]: d}))
import numpy as np
import pacjax as pj
from scene_space import build
from test_campaign import STRUCTURES
scene, controls = build(STRUCTURES["poly"], pickle.load(open("/work/notes/s26/poly_draw4.pkl", "rb")))
t = time.perf_counter()
eq = pj.solve_equilibrium(scene, controls, fallback=False)
eq.q.block_until_ready()
first = time.perf_counter() - t
warms = []
for _ in range(7):
    t = time.perf_counter()
    eq2 = pj.solve_equilibrium(scene, controls, fallback=False)
    eq2.q.block_until_ready()
    warms.append(time.perf_counter() - t)
warm = float(np.median(warms))
print(json.dumps({"tree": sys.argv[1], "first_s": round(first, 2), "warm_s": round(warm, 4),
  "compile_s": round(ev["backend_compile_duration"], 2), "result": pj.RESULTS[eq.result] or "successful",
  "steps": int(eq.steps), "q_hash": float(np.asarray(eq.q).sum())}))
