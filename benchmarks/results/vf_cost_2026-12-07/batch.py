import time, sys, os, jax, numpy as np
import pacjax as pj
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(9))
damping = pj.Damping.modal(scene)
rng = np.random.default_rng(0); n = int(sys.argv[1])
commands = np.zeros((n, 9)); commands[np.arange(n), rng.integers(0, 9, n)] = rng.uniform(0.01, 0.04, n)
f = lambda: pj.simulate_batch(scene, (0.0, 0.5), commands, q0=start.q, saveat=np.linspace(0, 0.5, 11), damping=damping)
t = time.perf_counter(); tr = f(); jax.block_until_ready(tr.q); c = time.perf_counter() - t
ts = []
for _ in range(2):
    t = time.perf_counter(); tr = f(); jax.block_until_ready(tr.q); ts.append(time.perf_counter() - t)
steps = np.asarray(tr.num_steps)
print(f"[{os.environ.get('XLA_FLAGS','')}] first {c:.2f} warm {ts} steps sum {steps.sum()} us/step {min(ts)/steps.sum()*1e6*2:.0f} (per core) aggregate {n*0.5/min(ts):.2f}x")
