import time, os, numpy as np, jax
import pacjax as pj
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
u = np.random.default_rng(0).uniform(0, 0.02, (1000, 9))
f = lambda: pj.solve_batch(scene, u, chunk_size=1000, tol=1e-10, fallback=False, progress=False)
jax.block_until_ready(f().q)
c0 = os.times(); t0 = time.perf_counter()
for _ in range(8): jax.block_until_ready(f().q)
c1 = os.times(); t1 = time.perf_counter()
cpu = (c1.user - c0.user) + (c1.system - c0.system)
print(f"wall {t1-t0:.2f} s, cpu {cpu:.2f} s, cores busy {cpu/(t1-t0):.2f}, per batch {(t1-t0)/8*1e3:.0f} ms, cpu per batch {cpu/8*1e3:.0f} ms")
