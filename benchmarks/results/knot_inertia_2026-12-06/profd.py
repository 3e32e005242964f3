import sys, os, time, glob, gzip, json, collections
import numpy as np, jax, jax.numpy as jnp
sys.argv = [sys.argv[0]] + sys.argv[1:]
exec(open('bw_setup.py').read())
w = int(sys.argv[1]); kind = sys.argv[2]
q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((w, n)))
v = jnp.asarray(0.1 * rng.standard_normal((w, n)))
from pacjax._jit import CPU_COMPILE_OPTIONS
f = jax.jit(jax.vmap(parts(kind))).lower(q, v).compile()
jax.block_until_ready(f(q, v))
d = f"/tmp/profd_{kind}_{w}"
os.system(f"rm -rf {d}")
with jax.profiler.trace(d, create_perfetto_trace=True):
    for _ in range(20): out = f(q, v)
    jax.block_until_ready(out)
fn = glob.glob(f"{d}/**/*.trace.json.gz", recursive=True)[0]
tr = json.load(gzip.open(fn))
ev = tr["traceEvents"] if isinstance(tr, dict) else tr
agg = collections.Counter(); cnt = collections.Counter()
for e in ev:
    if e.get("ph") == "X":
        agg[e["name"]] += e.get("dur", 0); cnt[e["name"]] += 1
tot = sum(agg.values())
for k, t in agg.most_common(40):
    print(f"{t/20:9.1f} us/call  n={cnt[k]//20:4d}  {k[:100]}")
