"""Timing prototype: the vector field with one linearisation of the segments' local kinematics
(the statics' `_linearise` on the energy plan's knots) serving the forces (structured gradient,
tendon rates from the tendon parts' Jacobians) and the inertia's Jacobians. The inertia is
lumped on the plan's knots with equal masses: for timing only (not the library's physics)."""
import time, sys, jax, jax.numpy as jnp, numpy as np, equinox as eqx, lineax as lx
jax.config.update("jax_enable_x64", True)
import pacjax as pj
from pacjax._dynamics import equations as E
from pacjax._model import inertia as I
from pacjax._model import hessian as H
from pacjax._model.kinematics import contract, chain_segments
from pacjax._model.rotation import matmul3, matvec3
from pacjax._dynamics.simulate import prepare
STEP = np.array([0.04, 0, 0, 0, 0, 0, 0, 0, 0.0])
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
damping = pj.Damping.modal(scene)
sc, damping, *_ = prepare(scene, 0.0, 0.5, np.array([0.0, 0.5]), damping, None, 1e-4, 1e-6, 10000, False, I.PHI_INERTIA_FACTOR, None)
model = E.EquationsOfMotion.build(sc, damping, I.PHI_INERTIA_FACTOR, jnp.float64)
u = jnp.asarray(STEP); ud = jnp.zeros(9)
q = jnp.zeros(12).at[0].set(0.3).at[4].set(0.2).at[8].set(-0.4).at[2].set(0.5); qd = jnp.ones(12) * 0.1
plan = sc.energy_plan()
K = plan.knots.s.shape[1]

def onepass(m, q, v):
    scene = m.scene
    consts = scene.constants(q.dtype)
    coords = scene.coordinates(q); vc = scene.coordinates(v)
    n, d = coords.shape
    g_el = jax.grad(lambda x: scene.coords_elastic_energy(x.reshape(n, d), consts))(coords.reshape(-1))
    lin = H._linearise(scene, coords, plan, consts, q.dtype)
    rates = jnp.einsum("ntd,nd->t", lin.jacobians[3], vc)
    springs = m._spring_controls(rates, u, ud)
    row_plan = plan.on_load_rows()
    seg_val, seg_jac = H._on_load_rows(plan, lin.values), H._on_load_rows(plan, lin.jacobians)
    lam_seg, _ = jax.grad(lambda local: scene.load_energy(local, springs, row_plan, consts))((seg_val, lin.traced_values))
    grad = scene.free_part(g_el.reshape(n, d) + jax.vmap(contract)(lam_seg, seg_jac))
    # the inertia's Jacobians from the same local frames
    rot, pos = lin.frames
    d_rot, d_pos = lin.jacobians[0], lin.jacobians[1]
    base_rot, base_pos = chain_segments(rot[:, -1], pos[:, -1], scene.robot.base_rotation, scene.robot.base_position)
    f = I._SegmentFrames(rot, d_rot, d_pos, base_rot, matmul3(base_rot[:, None], rot), base_pos[:, None] + matvec3(base_rot[:, None], pos))
    jac_pos, jac_ang = knot_jacobians_from(scene, f)
    masses = jnp.full(n * K, 0.01); moments = jnp.full((n * K, 3), 1e-6)
    frames = lambda x: tuple(a.reshape((-1,) + a.shape[2:]) for a in scene.knot_grid_frames(x, plan.knots))
    omega, acc, alpha = I._site_accelerations(frames, q, v)
    mm = "highest"
    euler = moments * alpha + jnp.cross(omega, moments * omega)
    bias = jnp.einsum("pia,p,pa->i", jac_pos, masses, acc, precision=mm) + jnp.einsum("pia,pa->i", jac_ang, euler, precision=mm)
    mass = I._mass_from_jacobians(scene, jac_pos, jac_ang, masses, moments, I.PHI_INERTIA_FACTOR)
    force = -grad - m.damping.stiffness * m.material_damping(q, v) - m.damping.mass * mass @ v - bias
    return lx.linear_solve(lx.MatrixLinearOperator(mass, lx.positive_semidefinite_tag), force, lx.Cholesky(), throw=False).value

import inspect
src = inspect.getsource(I._knot_jacobians)
src = src.replace("def _knot_jacobians(\n    scene: Scene, q: Float[Array, \" n_dofs\"], knots: Knots\n) -> tuple[Float[Array, \"k n_dofs 3\"], Float[Array, \"k n_dofs 3\"]]:", "def knot_jacobians_from(scene, f):")
src = src.replace("    f = _segment_frames(scene, q, knots)\n", "").replace("dtype = q.dtype", "dtype = f.rot.dtype")
ns = dict(vars(I)); exec(src, ns); knot_jacobians_from = ns["knot_jacobians_from"]

current = lambda m, q, v: m.accelerations(q, v, u, ud)
print("knots a segment", K, jax.block_until_ready(eqx.filter_jit(onepass)(model, q, qd))[:3])
N = 2000
for name, f in [("current", current), ("onepass", onepass)] * 3:
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
