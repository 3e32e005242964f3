exec(open('benchmarks/results/wide_kinematics_2026-12-07/setup.py').read())
import os, glob, gzip, json
sys.path.insert(0, 'benchmarks/results/wide_kinematics_2026-12-07'); from wide import Wide
lumped = I._knot_masses(sc, jnp.float64)
wd = Wide(sc, lumped, I.coordinate_inertia(sc, jnp.float64))
which = sys.argv[1]
fn_ = wd.dynamics if which == "wide" else (lambda q, v: I.body_dynamics(sc, q, v))
f = jax.jit(fn_).lower(q, qd).compile()
jax.block_until_ready(f(q, qd))
d = f"/tmp/prof_{which}"
os.system(f"rm -rf {d}")
with jax.profiler.trace(d, create_perfetto_trace=True):
    for _ in range(50): out = f(q, qd)
    jax.block_until_ready(out)
fn = glob.glob(f"{d}/**/*.trace.json.gz", recursive=True)[0]
tr = json.load(gzip.open(fn))
ev = tr["traceEvents"] if isinstance(tr, dict) else tr
agg = collections.Counter(); cnt = collections.Counter()
for e in ev:
    if e.get("ph") == "X":
        agg[e["name"]] += e.get("dur", 0); cnt[e["name"]] += 1
for k, t in agg.most_common(25):
    print(f"{t/50:9.1f} us/call  n={cnt[k]//50:4d}  {k[:100]}")
