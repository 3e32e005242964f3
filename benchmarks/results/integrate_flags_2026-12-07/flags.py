"""One first `simulate` of the 40 mm step (PAC, rtol 1e-4) under this process's XLA_FLAGS:
the XLA compile time of `integrate` (jax_log_compiles), the first call, and warm calls."""
import logging, os, re, time
import numpy as np, jax
jax.config.update("jax_log_compiles", True)
import pacjax as pj

xla = {}
class H(logging.Handler):
    def emit(self, r):
        m = re.search(r"Finished XLA compilation of (\S+) in ([\d.]+) s", r.getMessage())
        if m:
            xla[m.group(1)] = xla.get(m.group(1), 0.0) + float(m.group(2))
logging.getLogger("jax").addHandler(H()); logging.getLogger("jax").setLevel(logging.WARNING)
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
xla.clear()
run = lambda: pj.simulate(scene, (0.0, 0.5), np.array([0.04] + [0.0] * 8), q0=start.q,
                          saveat=np.linspace(0, 0.5, 11), damping=damping, rtol=1e-4)
t = time.perf_counter(); tr = jax.block_until_ready(run()); first = time.perf_counter() - t
warm = []
for _ in range(5):
    t = time.perf_counter(); jax.block_until_ready(run()); warm.append(time.perf_counter() - t)
ref = np.load(os.path.join(os.path.dirname(os.path.abspath(__file__)), "ref_tips.npy"))
tips = np.stack([np.asarray(pj.tip_pose(scene, q)[0]) for q in np.asarray(tr.q)])
err = np.max(np.linalg.norm(tips - ref, axis=1)) * 1e3
integ = {k: round(v, 2) for k, v in xla.items() if "integrate" in k}
print(f"flags={os.environ.get('XLA_FLAGS','')!r} first {first:.2f} xla {integ} warm median "
      f"{np.median(warm):.3f} min {min(warm):.3f} steps {int(tr.num_steps)} tip {err:.4f} mm",
      flush=True)
