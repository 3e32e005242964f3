exec(open("hist.py").read().split("@jax.jit")[0])
import rbx
rbx.LOG = []
solver = rbx.Rosenbrock23X(jacobian="differences", reuse=20, error_weight=opts.solver.error_weight, autonomous=True)
sol = jax.jit(lambda q0: diffrax.diffeqsolve(diffrax.ODETerm(S._TRACED_VECTOR_FIELD), solver, t0=0.0, t1=0.5, dt0=None, y0=(q0, jnp.zeros_like(q0)),
    saveat=diffrax.SaveAt(ts=[0.5]), stepsize_controller=diffrax.PIDController(rtol=1e-4, atol=1e-6), args=(model, STEP), max_steps=4096, throw=False))(q0)
L = np.array(rbx.LOG)
print(len(L), int(sol.stats["num_steps"]))
for a in (1, 2, 5, 10, 19):
    m = L[L[:, 2] == a, 1]
    print("age", a, np.round(np.quantile(m, [0.1, 0.5, 0.9]), 4))
w = (L[:, 0] > 0.35) & (L[:, 0] < 0.45)
print("window", np.round(np.quantile(L[w, 1], [0.1, 0.5, 0.9]), 4), "else", np.round(np.quantile(L[~w, 1], [0.1, 0.5, 0.9]), 4))
