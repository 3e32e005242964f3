import sys, time
import numpy as np, jax, jax.numpy as jnp
import equinox as eqx
import pacjax as pj
from pacjax._dynamics.simulate import prepare, default_solver
from pacjax._dynamics.equations import EquationsOfMotion, vector_field
from pacjax._model.inertia import body_dynamics
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
sc, dm, opts, span, ts = prepare(scene, 0.0, 0.5, [0.5], damping, default_solver(1e-4), 1e-4, 1e-6, 100000, False, 1e-6, None)
model = EquationsOfMotion.build(sc, dm, 1e-6, jnp.float64)
rng = np.random.default_rng(0)
n = scene.n_dofs
u0 = jnp.asarray(np.array([0.04] + [0.0]*8))
def parts(kind):
    def f(q, v):
        if kind == "vf":
            return vector_field(0.0, (q, v), (model, u0))[1]
        if kind == "body":
            M, b = body_dynamics(sc, q, v, 1e-6); return b + M.sum(0)
        if kind == "potgrad":
            return jax.grad(model.passive.potential_energy)(q, u0)
        if kind == "tendon":
            return model.tendon_forces(q, v, u0, jnp.zeros(9))
        if kind == "sitejac":
            from pacjax._model.inertia import _site_knots, _site_jacobians
            knots, _, _, _ = _site_knots(sc, q.dtype)
            a, b = _site_jacobians(sc, q, knots); return a.sum() + b.sum()
        if kind == "siteacc":
            from pacjax._model.inertia import _site_knots, _site_accelerations
            knots, (segs, s_), _, _ = _site_knots(sc, q.dtype)
            o, a, b = _site_accelerations(sc, segs, s_, q, v); return a.sum() + b.sum() + o.sum()
        if kind == "frames":
            from pacjax._model.inertia import _site_knots
            knots, (segs, s_), _, _ = _site_knots(sc, q.dtype)
            r, p = sc.frames(q, segs, s_); return r.sum() + p.sum()
        if kind == "pot+tendon":
            return jax.grad(model.passive.potential_energy)(q, u0) - model.tendon_forces(q, v, u0, jnp.zeros(9))
        if kind == "fused":
            l, rates = jax.jvp(sc.tendon_lengths, (q,), (v,))
            uu = model._spring_controls(rates, u0, jnp.zeros(9))
            return jax.grad(sc.potential_energy)(q, uu)
        if kind == "fused+damp":
            from pacjax._model.energy import strain_rate_energy
            l, rates = jax.jvp(sc.tendon_lengths, (q,), (v,))
            uu = model._spring_controls(rates, u0, jnp.zeros(9))
            def phi(x, w):
                r = strain_rate_energy(sc.model, sc.robot, sc.coordinates(jax.lax.stop_gradient(x)), sc.coordinates(w), sc.quadrature_points)
                return sc.potential_energy(x, uu) + 0.01 * r
            a, b = jax.grad(phi, argnums=(0, 1))(q, v)
            return a + b
        if kind == "fused,damp":
            l, rates = jax.jvp(sc.tendon_lengths, (q,), (v,))
            uu = model._spring_controls(rates, u0, jnp.zeros(9))
            return jax.grad(sc.potential_energy)(q, uu) + 0.01 * model.material_damping(q, v)
        if kind == "fused_res":
            from pacjax._model.hessian import energy_derivatives
            l, rates = jax.jvp(sc.tendon_lengths, (q,), (v,))
            uu = model._spring_controls(rates, u0, jnp.zeros(9))
            return jax.grad(sc.potential_energy)(q, uu)
        if kind == "matdamp":
            return model.material_damping(q, v)
    return f
W = [int(sys.argv[1])]
for kind in sys.argv[2].split(":"):
    for w in W:
        q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((w, n)))
        v = jnp.asarray(0.1 * rng.standard_normal((w, n)))
        f = jax.jit(jax.vmap(parts(kind)))
        jax.block_until_ready(f(q, v))
        ts_ = []
        for r in range(5):
            t = time.perf_counter()
            for _ in range(50): out = f(q, v)
            jax.block_until_ready(out); ts_.append((time.perf_counter() - t) / 50)
        m = np.median(ts_)
        print(f"{kind:8s} width {w:3d}: {m*1e3:.3f} ms/call, {m/w*1e6:.1f} us/row", flush=True)

q = jnp.asarray(start.q); v = jnp.asarray(0.1 * rng.standard_normal(n))
a = parts("pot+tendon")(q, v); b = parts("fused")(q, v)
print("diff", float(jnp.max(jnp.abs(a - b))), float(jnp.max(jnp.abs(a))))
