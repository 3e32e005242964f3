import glob, gzip, json, collections, re, sys
d = sys.argv[1]; reps = int(sys.argv[2])
fn = glob.glob(f"{d}/**/*.trace.json.gz", recursive=True)[0]
tr = json.load(gzip.open(fn)); ev = tr["traceEvents"] if isinstance(tr, dict) else tr
agg = collections.Counter(); cnt = collections.Counter()
skip = ("$", "Thunk", "Pjit", "Common", "end:")
for e in ev:
    if e.get("ph") == "X" and not e["name"].startswith(skip):
        k = re.sub(r"\.\d+$", "", e["name"])
        agg[k] += e.get("dur", 0); cnt[k] += 1
print("total thunks/call", sum(cnt.values())/reps, "sum us/call", sum(agg.values())/reps)
for k, t in agg.most_common(30):
    print(f"{t/reps:8.1f} us  n={cnt[k]/reps:6.1f}  {k}")
