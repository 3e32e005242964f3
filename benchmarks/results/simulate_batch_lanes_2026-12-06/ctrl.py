import sys, time, functools, statistics
import numpy as np, jax, diffrax
import pacjax as pj
import pacjax._dynamics.simulate as S
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
STEP = np.array([0.04] + [0.0] * 8)
saveat = np.linspace(0, 0.5, 11)
def tips(tr): return np.stack([np.asarray(pj.tip_pose(scene, q)[0]) for q in np.asarray(tr.q)])
ref = pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=saveat, damping=damping, rtol=1e-7, atol=1e-9, solver=pj.dynamics.rosenbrock23())
rt = tips(ref)
Orig = diffrax.PIDController
variants = {"default": {}, "fmax5": dict(factormax=5.0), "fmax3": dict(factormax=3.0), "safety0.8": dict(safety=0.8), "fmax2": dict(factormax=2.0)}
names = sys.argv[1:] or list(variants)
variants.update({"safety0.7": dict(safety=0.7), "safety0.6": dict(safety=0.6)})
for name in names:
    kw = variants[name]
    S.diffrax.PIDController = lambda **k: Orig(**{**k, **kw})
    run = lambda: pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=saveat, damping=damping)
    tr = run(); jax.block_until_ready(tr)
    walls = []
    for _ in range(5):
        t = time.perf_counter(); tr = run(); jax.block_until_ready(tr); walls.append(time.perf_counter() - t)
    err = 1e3 * float(np.max(np.linalg.norm(tips(tr) - rt, axis=1)))
    print(f"{name:10s} steps {int(tr.num_steps)} accepted {int(tr.num_accepted_steps)} warm {statistics.median(walls):.3f} s tip err {err:.4f} mm", flush=True)
