import time, sys, jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
import pacjax as pj, equinox as eqx
from pacjax._dynamics.equations import EquationsOfMotion
from pacjax._model.inertia import body_dynamics, PHI_INERTIA_FACTOR
from pacjax._model.inputs import as_traced_leaves

STEP = np.array([0.04, 0, 0, 0, 0, 0, 0, 0, 0.0])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(9)); end = pj.solve_equilibrium(scene, STEP)
damping = pj.Damping.modal(scene)
traj = pj.simulate(scene, (0.0, 0.1), STEP, q0=start.q, saveat=np.array([0.0, 0.1]), damping=damping)
q = jnp.asarray(np.asarray(traj.q)[-1]); qd = jnp.asarray(np.asarray(traj.qdot)[-1])
from pacjax._dynamics.simulate import prepare
sc, damping, *_ = prepare(scene, 0.0, 0.5, np.array([0.0, 0.5]), damping, None, 1e-4, 1e-6, 10000, False, PHI_INERTIA_FACTOR, None)
model = EquationsOfMotion.build(sc, damping, PHI_INERTIA_FACTOR, jnp.float64)
u = jnp.asarray(STEP); ud = jnp.zeros(9)
from pacjax._model import inertia as I
def accs(m, q, v):
    lumped = I._knot_masses(m.scene, q.dtype)
    frames = I._knot_world_frames(m.scene, lumped.knots)
    o, a, al = I._site_accelerations(frames, q, v)
    return jnp.sum(o) + jnp.sum(a) + jnp.sum(al)
def frames0(m, q, v):
    lumped = I._knot_masses(m.scene, q.dtype)
    r, p = I._knot_world_frames(m.scene, lumped.knots)(q)
    return jnp.sum(r) + jnp.sum(p)
def frames1(m, q, v):
    lumped = I._knot_masses(m.scene, q.dtype)
    (r, p), (dr, dp) = jax.jvp(I._knot_world_frames(m.scene, lumped.knots), (q,), (v,))
    return jnp.sum(dr) + jnp.sum(dp)
def jacs(m, q, v):
    lumped = I._knot_masses(m.scene, q.dtype)
    a, b = I._knot_jacobians(m.scene, q, lumped.knots)
    return jnp.sum(a) + jnp.sum(b)
def segf(m, q, v):
    lumped = I._knot_masses(m.scene, q.dtype)
    f = I._segment_frames(m.scene, q, lumped.knots)
    return sum(jnp.sum(x) for x in f)
parts = {"accelerations": lambda m, q, v: m.accelerations(q, v, u, ud),
 "M": lambda m, q, v: I.mass_matrix(m.scene, q),
 "bias": lambda m, q, v: body_dynamics(m.scene, q, v)[1],
 "site accelerations": accs, "frames": frames0, "frames jvp": frames1, "knot jacobians": jacs, "segment frames": segf}
N = 2000
for name, f in parts.items():
    @eqx.filter_jit
    def loop(m, q, v, f=f):
        def body(i, c):
            q, v = c
            r = f(m, q, v)
            return q + 1e-14 * jnp.sum(r), v + 1e-14 * jnp.sum(r)
        return jax.lax.fori_loop(0, N, body, (q, v))
    t = time.perf_counter(); jax.block_until_ready(loop(model, q, qd)); c = time.perf_counter() - t
    ts = []
    for _ in range(5):
        t = time.perf_counter(); jax.block_until_ready(loop(model, q, qd)); ts.append(time.perf_counter() - t)
    print(f"{name:20s} {np.median(ts)/N*1e6:8.1f} us  (min {min(ts)/N*1e6:.1f}; compile {c:.1f} s)", flush=True)
