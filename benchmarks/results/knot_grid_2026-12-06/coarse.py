# VF cost and one simulate with coarser kinematics/quadrature: env QP, MININT, NODES.
import os, sys, time, json, statistics
import numpy as np, jax, jax.numpy as jnp
import pacjax._model.kinematics as K
K._MIN_INTERVALS = int(os.environ.get("MININT", 8)); K._INTERVAL_NODES = int(os.environ.get("NODES", 4))
import pacjax as pj
import pacjax._model.inertia as I
INQP = int(os.environ.get("INQP", 0))
if INQP:
    _gl = I.gauss_legendre
    I.gauss_legendre = lambda n: _gl(INQP)
from pacjax._dynamics.simulate import prepare, default_solver
from pacjax._dynamics.equations import EquationsOfMotion, vector_field
QP = int(os.environ.get("QP", 8))
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2, quadrature_points=QP)
print(K.__file__, 'QP', QP, 'MININT', K._MIN_INTERVALS, 'NODES', K._INTERVAL_NODES, 'INQP', INQP)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
ref0 = pj.solve_equilibrium(pj.presets.stella2023(pj.PAC(), tip_mass=0.2), np.array([0.04]+[0.0]*8))
damping = pj.Damping.modal(scene)
sc, dm, opts, span, ts = prepare(scene, 0.0, 0.5, [0.5], damping, default_solver(1e-4), 1e-4, 1e-6, 100000, False, 1e-6, None)
model = EquationsOfMotion.build(sc, dm, 1e-6, jnp.float64)
n = scene.n_dofs; rng = np.random.default_rng(0)
u0 = jnp.asarray(np.array([0.04] + [0.0]*8))
f = lambda q, v: vector_field(0.0, (q, v), (model, u0))[1]
for w in (1, 16):
    q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((w, n)))
    v = jnp.asarray(0.1 * rng.standard_normal((w, n)))
    c = jax.jit(jax.vmap(f)).lower(q, v).compile()
    ca = c.cost_analysis(); ca = ca[0] if isinstance(ca, list) else ca
    jax.block_until_ready(c(q, v)); t_ = []
    for r in range(7):
        t = time.perf_counter()
        for _ in range(30): o = c(q, v)
        jax.block_until_ready(o); t_.append((time.perf_counter() - t) / 30)
    print(f"w {w} flops/row {ca.get('flops',0)/w:.0f} bytes/row {ca.get('bytes accessed',0)/w:.0f} us/row {np.median(t_)/w*1e6:.1f}", flush=True)
STEP = np.array([0.04] + [0.0] * 8); tsv = np.linspace(0, 0.5, 11)
ref = np.load("ref_tips.npy")
walls = []
for k in range(3):
    t = time.perf_counter(); tr = pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=tsv, damping=damping, rtol=1e-4); jax.block_until_ready(tr); walls.append(time.perf_counter() - t)
tips = np.stack([np.asarray(pj.tip_pose(scene, q)[0]) for q in np.asarray(tr.q)])
print(json.dumps(dict(first=round(walls[0],2), warm=round(statistics.median(walls[1:]),3), steps=int(tr.num_steps), err_mm=float(np.max(np.linalg.norm(tips - ref, axis=1))*1e3))))
eq = pj.solve_equilibrium(scene, STEP)
print("equilibrium tip diff mm", float(np.linalg.norm(np.asarray(pj.tip_pose(scene, eq.q)[0]) - np.asarray(pj.tip_pose(ref0.scene if hasattr(ref0,'scene') else pj.presets.stella2023(pj.PAC(), tip_mass=0.2), ref0.q)[0]))*1e3))
