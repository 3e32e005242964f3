import sys, re, collections
exec(open('bw_setup.py').read())
w = 1
q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((w, n)))
v = jnp.asarray(0.1 * rng.standard_normal((w, n)))
txt = jax.jit(jax.vmap(parts(sys.argv[1]))).lower(q, v).compile().as_text()
open('/tmp/vf_hlo.txt', 'w').write(txt)
# find the computations fused_computation for bitcast_slice_fusion instrs: map instr line -> metadata
c = collections.Counter()
for line in txt.splitlines():
    m = re.search(r"(%?\S*bitcast_slice_fusion\S*) = .*calls=(\S+)", line)
    if m and "ENTRY" not in line:
        md = re.search(r'op_name="([^"]*)"', line); sf = re.search(r'source_file="([^"]*)" source_line=(\d+)', line)
        key = (md.group(1)[-80:] if md else "?") + " | " + (sf.group(1).split('/')[-1] + ":" + sf.group(2) if sf else "?")
        c[key] += 1
for k, n_ in c.most_common(40): print(n_, k)
