import time, jax, jax.numpy as jnp, numpy as np, diffrax, equinox as eqx
jax.config.update("jax_enable_x64", True)
from pacjax._dynamics.rosenbrock import Rosenbrock23
n = 12
rng = np.random.default_rng(0)
K = rng.normal(size=(n, n)); K = K @ K.T + n * np.eye(n); K *= 1e3 / np.linalg.eigvalsh(K).min()
K = jnp.asarray(K)
def vf(t, y, args):
    q, v = y
    return v, -K @ q - 0.02 * K @ v
@eqx.filter_jit
def run(y0):
    solver = Rosenbrock23(jacobian="differences", reuse=20, autonomous=True, loop="checkpointed")
    sol = diffrax.diffeqsolve(diffrax.ODETerm(vf), solver, t0=0.0, t1=0.5, dt0=1e-6, y0=y0,
        saveat=diffrax.SaveAt(ts=jnp.linspace(0, 0.5, 11)), stepsize_controller=diffrax.PIDController(rtol=1e-4, atol=1e-6),
        max_steps=100000, throw=False)
    return sol.ys, sol.stats["num_steps"]
y0 = (jnp.ones(n), jnp.zeros(n))
out = run(y0); jax.block_until_ready(out)
ts = []
for _ in range(5):
    t = time.perf_counter(); out = run(y0); jax.block_until_ready(out); ts.append(time.perf_counter() - t)
steps = int(out[1]); print("steps", steps, "median s", np.median(ts), "us/step", np.median(ts) / steps * 1e6)
