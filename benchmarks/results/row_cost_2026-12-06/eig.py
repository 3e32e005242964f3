exec(open("/work/main/benchmarks/results/knot_inertia_2026-12-06/bw_setup.py").read())
from jax.flatten_util import ravel_pytree
q0 = jnp.asarray(start.q); v0 = jnp.zeros_like(q0)
traj = np.load("traj.npy")
for k in (0, 10, 50, 200):
    q = jnp.asarray(traj[k]) if k else q0
    y = (q, v0)
    x, unr = ravel_pytree(y)
    J = jax.jacfwd(lambda z: ravel_pytree(vector_field(0.0, unr(z), (model, u0)))[0])(x)
    ev = np.linalg.eigvals(np.asarray(J))
    idx = np.argsort(-np.abs(ev))
    print(k, " ".join(f"{ev[i].real:.0f}{ev[i].imag:+.0f}j" for i in idx[::2]))
