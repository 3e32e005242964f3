import sys, time, dataclasses, numpy as np, jax
import pacjax as pj
name = sys.argv[1]
model_ = {"PAC": pj.PAC(), "PCC": pj.PCC(), "P1": pj.PolynomialCurvature(1), "P2": pj.PolynomialCurvature(2)}[name]
scene = pj.presets.stella2023(model_, tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
STEP = np.array([0.04] + [0.0] * 8)
ts = np.linspace(0, 0.5, 11)
ref = pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=ts, damping=damping, rtol=1e-8, atol=1e-10, solver=pj.dynamics.rosenbrock23(), max_steps=1_000_000)
tref = np.stack([np.asarray(pj.tip_pose(scene, q)[0]) for q in ref.q])
print(name, "reference steps", int(ref.num_steps))
for rtol in [1e-4, 1e-3]:
  for filt in [False, True, False, True]:
    solver = dataclasses.replace(pj.dynamics.rosenbrock23(), filter_error=filt)
    run = lambda: pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=ts, damping=damping, solver=solver, rtol=rtol)
    tr = run(); jax.block_until_ready(tr)
    w = []
    for _ in range(3):
        t = time.perf_counter(); tr = run(); jax.block_until_ready(tr); w.append(time.perf_counter() - t)
    tips = np.stack([np.asarray(pj.tip_pose(scene, q)[0]) for q in tr.q])
    err = np.max(np.linalg.norm(tips - tref, axis=1)) * 1e3
    print(f"  rtol {rtol:g} filter {filt}: steps {int(tr.num_steps)} acc {int(tr.num_accepted_steps)} warm {np.median(w):.3f} s tip err max {err:.4f} mm")
