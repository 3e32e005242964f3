import re, sys, time, os
import numpy as np, jax, jax.numpy as jnp
import pacjax as pj
from pacjax._dynamics import simulate as S
from pacjax._dynamics import rosenbrock as R
mode = sys.argv[1]
if mode == "eye":
    R.forward_differences = lambda f, x, fx=None: jnp.eye(x.size, dtype=x.dtype) + 0 * x[0]
print(pj.__file__, mode, flush=True)
STEP = np.array([0.04, 0, 0, 0, 0, 0, 0, 0, 0.0])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
dtype = jnp.float64
controls = S.check_simulation_controls(scene, STEP, 0.0, dtype)
q0 = S.check_q(scene, start.q, dtype); qdot0 = S.check_qdot(scene, None, dtype)
sc, damping, opts, span, ts = S.prepare(scene, 0.0, 0.5, np.linspace(0, .5, 11), damping, None, 1e-4, 1e-6, 100000, False, S.PHI_INERTIA_FACTOR, None)
t = time.perf_counter(); low = S.integrate.lower(sc, damping, controls, q0, qdot0, span, ts, None, opts); tl = time.perf_counter() - t
copts = {"xla_cpu_use_fusion_emitters": False} if "classic" in sys.argv[2:] else None
if "O1" in sys.argv[2:]: copts = dict(copts or {}, xla_backend_optimization_level=1)
t = time.perf_counter(); comp = low.compile(copts) if copts else low.compile(); tc = time.perf_counter() - t
opt = comp.compiled.as_text() if hasattr(comp, "compiled") else comp.as_text()
print(f"{mode} {sys.argv[2:]}: lower {tl:.1f} s compile {tc:.1f} s getrf {len(re.findall('getrf', opt))} potrf {len(re.findall('potrf|cholesky', opt))} lines {opt.count(chr(10))}", flush=True)

if mode == "base":
    runs = []
    for _ in range(3):
        t = time.perf_counter(); tr = comp(sc, damping, controls, q0, qdot0, span, ts, None, opts); jax.block_until_ready(tr); runs.append(time.perf_counter()-t)
    print(f"warm {[round(r,3) for r in runs]} steps {int(tr.num_steps)}", flush=True)
