import time, sys, jax, jax.numpy as jnp, numpy as np, equinox as eqx
jax.config.update("jax_enable_x64", True)
import pacjax as pj
from pacjax._dynamics import equations as E
from pacjax._model import inertia as I
from pacjax._model import hessian as H
from pacjax._model.kinematics import contract
from pacjax._dynamics.simulate import prepare
STEP = np.array([0.04, 0, 0, 0, 0, 0, 0, 0, 0.0])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
damping = pj.Damping.modal(scene)
sc, damping, *_ = prepare(scene, 0.0, 0.5, np.array([0.0, 0.5]), damping, None, 1e-4, 1e-6, 10000, False, I.PHI_INERTIA_FACTOR, None)
model = E.EquationsOfMotion.build(sc, damping, I.PHI_INERTIA_FACTOR, jnp.float64)
u = jnp.asarray(STEP); ud = jnp.zeros(9)
q = jnp.zeros(12).at[0].set(0.3).at[4].set(0.2).at[8].set(-0.4).at[2].set(0.5); qd = jnp.ones(12) * 0.1

def structured(m, q, v):
    scene = m.scene
    consts = scene.constants(q.dtype)
    coords = scene.coordinates(q); vc = scene.coordinates(v)
    n, d = coords.shape
    g_el = jax.grad(lambda x: scene.coords_elastic_energy(x.reshape(n, d), consts))(coords.reshape(-1))
    plan = scene.energy_plan()
    lin = H._linearise(scene, coords, plan, consts, q.dtype)
    parts_jac = lin.jacobians[3]
    rates = jnp.einsum("ntd,nd->t", parts_jac, vc)
    springs = m._spring_controls(rates, u, ud)
    row_plan = plan.on_load_rows()
    seg_val, seg_jac = H._on_load_rows(plan, lin.values), H._on_load_rows(plan, lin.jacobians)
    lam_seg, lam_tr = jax.grad(lambda local: scene.load_energy(local, springs, row_plan, consts))((seg_val, lin.traced_values))
    grad = jax.vmap(contract)(lam_seg, seg_jac)
    return scene.free_part((g_el.reshape(n, d) + grad))

def current(m, q, v):
    rates = jax.jvp(m.scene.tendon_lengths, (q,), (v,))[1]
    springs = m._spring_controls(rates, u, ud)
    return jax.grad(m.scene.potential_energy)(q, springs)

a = eqx.filter_jit(structured)(model, q, qd); b = eqx.filter_jit(current)(model, q, qd)
print("max diff", float(jnp.max(jnp.abs(a - b))), float(jnp.max(jnp.abs(b))))
N = 2000
def fwd(m, q, v):
    rates = jax.jvp(m.scene.tendon_lengths, (q,), (v,))[1]
    springs = m._spring_controls(rates, u, ud)
    return jax.jacfwd(m.scene.potential_energy)(q, springs)
c = eqx.filter_jit(fwd)(model, q, qd); print("fwd diff", float(jnp.max(jnp.abs(c - b))))
for name, f in [("current", current), ("jacfwd", fwd)] * 2:
    @eqx.filter_jit
    def loop(m, q, v, f=f):
        def body(i, c):
            q, v = c
            r = f(m, q, v)
            return q + 1e-14 * jnp.sum(r), v + 1e-14 * jnp.sum(r)
        return jax.lax.fori_loop(0, N, body, (q, v))
    jax.block_until_ready(loop(model, q, qd))
    ts = []
    for _ in range(7):
        t = time.perf_counter(); jax.block_until_ready(loop(model, q, qd)); ts.append(time.perf_counter() - t)
    print(f"{name:10s} {np.median(ts)/N*1e6:7.1f} us (min {min(ts)/N*1e6:.1f})", flush=True)
