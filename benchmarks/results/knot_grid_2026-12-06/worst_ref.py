import sys, time
sys.path.insert(0, "/work/main/benchmarks")
import numpy as np, pacjax as pj, jax
from bench_dynamics import _batch_commands
sc = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
a = np.load('b2_old1.npy'); b = np.load('b2_new1.npy')
tp = jax.jit(jax.vmap(lambda q: pj.tip_pose(sc, q)[0]))
ta, tb = np.asarray(tp(a)), np.asarray(tp(b))
d = np.linalg.norm(ta - tb, axis=1)
rows = np.argsort(d)[-3:]
cmds = np.asarray(_batch_commands(64))
start = pj.solve_equilibrium(sc, np.zeros(sc.n_tendons))
damping = pj.Damping.modal(sc)
for r in rows:
    t = time.time()
    ref = pj.simulate(sc, (0.0, 0.5), cmds[r], q0=start.q, saveat=[0.5], damping=damping, rtol=1e-7, atol=1e-9)
    tr = np.asarray(pj.tip_pose(sc, np.asarray(ref.q)[-1])[0])
    print(f"row {r} cmd {cmds[r].round(3)} old-new {d[r]*1e3:.4f} mm; old-ref {np.linalg.norm(ta[r]-tr)*1e3:.4f} mm; new-ref {np.linalg.norm(tb[r]-tr)*1e3:.4f} mm ({time.time()-t:.0f} s, {int(ref.num_steps)} steps)", flush=True)
