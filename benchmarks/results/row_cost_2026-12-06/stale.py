import sys
exec(open("hist.py").read().split("@jax.jit")[0])
import rbx
ref = None
for th in [float(x) for x in sys.argv[1].split(",")]:
    rbx.THRESH = th
    solver = rbx.Rosenbrock23X(jacobian="differences", reuse=int(sys.argv[2]) if len(sys.argv) > 2 else 20, error_weight=opts.solver.error_weight, autonomous=True)
    sol = jax.jit(lambda q0: diffrax.diffeqsolve(diffrax.ODETerm(S._TRACED_VECTOR_FIELD), solver, t0=0.0, t1=0.5, dt0=None, y0=(q0, jnp.zeros_like(q0)),
        saveat=diffrax.SaveAt(ts=[0.5], solver_state=True), stepsize_controller=diffrax.PIDController(rtol=1e-4, atol=1e-6), args=(model, STEP), max_steps=4096, throw=False))(q0)
    s, a = int(sol.stats["num_steps"]), int(sol.stats["num_accepted_steps"])
    # nj not returned; approximate via solver state unavailable -> recompute: use final state? print steps only
    nj = int(sol.solver_state[-1]); print(th, "steps", s, "acc", a, "J", nj, "VFeq", 2*s + 24*nj, np.asarray(sol.ys[0][-1][:3]), flush=True)
