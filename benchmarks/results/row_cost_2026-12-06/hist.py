import numpy as np, jax, jax.numpy as jnp, diffrax, dataclasses
import pacjax as pj
from pacjax._dynamics import simulate as S
from pacjax._dynamics.equations import EquationsOfMotion
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
STEP = jnp.asarray(np.array([0.04] + [0.0] * 8))
sc, dm, opts, span, ts = S.prepare(scene, 0.0, 0.5, [0.5], damping, S.default_solver(1e-4), 1e-4, 1e-6, 100000, False, 1e-6, None)
q0 = S.aligned_rest_start(sc, STEP, jnp.asarray(start.q), jnp.zeros(scene.n_dofs), 0.0)
model = EquationsOfMotion.build(sc, dm, 1e-6, jnp.float64)
solver = dataclasses.replace(opts.solver, autonomous=True)
@jax.jit
def run(q0):
    return diffrax.diffeqsolve(diffrax.ODETerm(S._TRACED_VECTOR_FIELD), solver, t0=0.0, t1=0.5, dt0=None, y0=(q0, jnp.zeros_like(q0)),
        saveat=diffrax.SaveAt(steps=True), stepsize_controller=diffrax.PIDController(rtol=1e-4, atol=1e-6), args=(model, STEP), max_steps=4096, throw=False)
sol = run(q0)
t = np.asarray(sol.ts); t = t[np.isfinite(t)]
print("accepted", len(t), sol.stats["num_steps"])
for edge in (0.001, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5):
    print(f"t<= {edge}: {np.sum(t <= edge)}")
h = np.diff(np.concatenate([[0], t]))
np.save("hist_t.npy", t)
print("h quantiles", np.quantile(h, [0.1, 0.5, 0.9]))
for r in (1, 20):
    solver = dataclasses.replace(opts.solver, autonomous=True, reuse=r)
    sol = jax.jit(lambda q0: diffrax.diffeqsolve(diffrax.ODETerm(S._TRACED_VECTOR_FIELD), solver, t0=0.0, t1=0.5, dt0=None, y0=(q0, jnp.zeros_like(q0)),
        saveat=diffrax.SaveAt(steps=True), stepsize_controller=diffrax.PIDController(rtol=1e-4, atol=1e-6), args=(model, STEP), max_steps=4096, throw=False))(q0)
    t = np.asarray(sol.ts); t = t[np.isfinite(t)]
    counts = np.histogram(t, bins=np.linspace(0, 0.5, 11))[0]
    print("reuse", r, "accepted per 50 ms", counts.tolist())
    qs = np.asarray(sol.ys[0])[:len(t)]
    if r == 20:
        i = np.searchsorted(t, [0.1, 0.2, 0.3, 0.4, 0.45, 0.5])
        for k in i[:-1]:
            print(round(t[k],3), np.round(qs[k], 4).tolist())
