import time, json, statistics, os, sys
import numpy as np, jax, jax.numpy as jnp
import pacjax as pj
import pacjax._dynamics.rosenbrock as R
if os.environ.get("VMAPJ"):
    def fd(f, x, fx=None):
        steps = jnp.sqrt(jnp.finfo(x.dtype).eps) * jnp.maximum(jnp.abs(x), 1.0)
        moved = jnp.concatenate([jnp.zeros((1, x.size), x.dtype), jnp.diag(steps)])
        values = jax.vmap(lambda dx: f(x + dx))(moved)
        return ((values[1:] - values[0]) / steps[:, None]).T
    R.forward_differences = fd
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
STEP = np.array([0.04] + [0.0] * 8)
ts = np.linspace(0, 0.5, 11)
def run(rtol=1e-4):
    return pj.simulate(scene, (0.0, 0.5), STEP, q0=start.q, saveat=ts, damping=damping, rtol=rtol)
def tips(tr):
    return np.stack([np.asarray(pj.tip_pose(scene, q)[0]) for q in np.asarray(tr.q)])
ref = np.load("ref_tips.npy")
walls = []
for k in range(6):
    t = time.perf_counter(); tr = run(); jax.block_until_ready(tr); walls.append(time.perf_counter() - t)
err = np.max(np.linalg.norm(tips(tr) - ref, axis=1)) * 1e3
print(os.environ.get("TAG"), json.dumps(dict(first=round(walls[0],2), warm=round(statistics.median(walls[1:]),3), steps=int(tr.num_steps), acc=int(tr.num_accepted_steps), err_mm=round(float(err),4))), flush=True)
