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
parts = {
 "accelerations": lambda m, q, v: m.accelerations(q, v, u, ud),
 "body_dynamics": lambda m, q, v: body_dynamics(m.scene, q, v)[1] + body_dynamics(m.scene, q, v)[0][0],
 "forces(M given)": lambda m, q, v: m.forces(q, v, u, ud, jnp.eye(q.shape[0])),
 "grad potential": lambda m, q, v: jax.grad(m.scene.potential_energy)(q, u),
 "tendon jvp": lambda m, q, v: jax.jvp(m.scene.tendon_lengths, (q,), (v,))[1].sum() * q,
 "material damping": lambda m, q, v: m.material_damping(q, v),
 "stiff_jacobian": lambda m, q, v: m.stiff_jacobian(q, v, u, ud)[0:12, 12],
}

for name, f in parts.items():
    g = eqx.filter_jit(f)
    t = time.perf_counter(); jax.block_until_ready(g(model, q, qd)); c = time.perf_counter() - t
    ts = []
    for _ in range(7):
        t = time.perf_counter()
        for _ in range(300):
            r = g(model, q, qd)
        jax.block_until_ready(r); ts.append((time.perf_counter() - t) / 300)
    print(f"{name:20s} {np.median(ts)*1e6:8.1f} us  (min {min(ts)*1e6:.1f}; compile {c:.1f} s)", flush=True)
