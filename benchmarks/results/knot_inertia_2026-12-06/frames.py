import re, collections, sys
txt = open('/tmp/vf_hlo.txt').read()
lines = txt.splitlines()
# parse FileNames, FunctionNames, FileLocations, StackFrames
sec = None; files = {}; funcs = {}; locs = {}; frames = {}
for l in lines:
    s = l.strip()
    if s in ("FileNames", "FunctionNames", "FileLocations", "StackFrames"): sec = s; continue
    if not s or s.startswith(("HloModule", "%", "ROOT", "ENTRY", "}")): 
        if s.startswith(("HloModule","%","ENTRY")): sec = None
        continue
    m = re.match(r"(\d+) (.*)", s)
    if not m or sec is None: continue
    i, rest = int(m.group(1)), m.group(2)
    if sec == "FileNames": files[i] = rest.strip('"')
    elif sec == "FunctionNames": funcs[i] = rest.strip('"')
    elif sec == "FileLocations":
        mm = re.search(r"file_name_id=(\d+) function_name_id=(\d+) line=(\d+)", rest); locs[i] = (int(mm.group(1)), int(mm.group(2)), int(mm.group(3)))
    elif sec == "StackFrames":
        mm = re.search(r"file_location_id=(\d+) parent_frame_id=(\d+)", rest); frames[i] = (int(mm.group(1)), int(mm.group(2)))
def stack(fid, depth=4):
    out = []
    steps = 0
    while fid in frames and len(out) < depth and steps < 200:
        steps += 1
        loc, parent = frames[fid]
        f, fn, ln = locs[loc]
        if 'pacjax' in files[f]: out.append(f"{files[f].split('pacjax/')[-1]}:{ln}({funcs[fn]})")
        fid = parent
    return " < ".join(out)
pat = sys.argv[1]
c = collections.Counter()
for l in lines:
    if pat in l and "calls=" in l and "stack_frame_id" in l and not l.strip().startswith("ROOT"):
        fid = int(re.search(r"stack_frame_id=(\d+)", l).group(1))
        c[stack(fid)] += 1
for k, n in c.most_common(25): print(n, k)
