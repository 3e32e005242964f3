import re, collections, glob, gzip, json, sys
hlo = open(glob.glob('/tmp/dump/*jit_integrate.cpu_after_optimizations.txt')[0]).read()
lines = hlo.splitlines()
src = open('frames.py').read().split("pat = sys.argv[1]")[0].replace("txt = open('/tmp/vf_hlo.txt').read()", "txt = hlo")
exec(src)
# map instruction name -> stack (all computations, not only fused bodies: thunks are top-level instrs of entry, while bodies, conditionals, calls)
name2st = {}
for l in lines:
    m = re.match(r"\s*(?:ROOT )?%?([\w.\-]+) = .*stack_frame_id=(\d+)", l)
    if m: name2st[m.group(1)] = stack(int(m.group(2)), 6)
fn = glob.glob("/tmp/prof_sim/**/*.trace.json.gz", recursive=True)[0]
tr = json.load(gzip.open(fn)); ev = tr["traceEvents"] if isinstance(tr, dict) else tr
agg = collections.Counter(); cnt = collections.Counter(); tot = 0
depth = int(sys.argv[1]) if len(sys.argv) > 1 else 1
for e in ev:
    if e.get("ph") != "X": continue
    nm = e["name"]
    if nm in name2st:
        st = name2st[nm].split(" < ")
        key = " < ".join(st[:depth]) if st[0] else "(no pacjax frame)"
        # find the outermost known pacjax-level function for grouping
        agg[key] += e["dur"]; cnt[key] += 1; tot += e["dur"]
print("total thunk us", tot, "thunks", sum(cnt.values()))
for k, t in agg.most_common(int(sys.argv[2]) if len(sys.argv) > 2 else 40):
    print(f"{t/1e3:8.1f} ms {cnt[k]:7d} {k}")
