import sys, time
import numpy as np, jax, jax.numpy as jnp
import pacjax as pj
from pacjax._dynamics.simulate import prepare, default_solver
from pacjax._dynamics.equations import EquationsOfMotion, vector_field
from pacjax._model import inertia as I
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
        if kind == "struct":
            M, b = I.structured_body_dynamics(sc, q, v, 1e-6); return b + M.sum(0)
        if kind == "chained":
            M, b = I.chained_body_dynamics(sc, q, v, 1e-6); return b + M.sum(0)
        if kind == "solve":
            M, b = I.structured_body_dynamics(sc, q, v, 1e-6); return jnp.linalg.solve(M, b)
        if kind == "cho":
            M, b = I.structured_body_dynamics(sc, q, v, 1e-6); return jax.scipy.linalg.cho_solve(jax.scipy.linalg.cho_factor(M), b)
        if kind == "fused":
            l, rates = jax.jvp(sc.tendon_lengths, (q,), (v,))
            uu = model._spring_controls(rates, u0, jnp.zeros(9))
            return jax.grad(sc.potential_energy)(q, uu)
        if kind == "sitejac":
            knots, _, _, _ = I._site_knots(sc, q.dtype)
            a, b = I._site_jacobians(sc, q, knots); return a.sum() + b.sum()
        if kind == "siteacc":
            knots, (segs, s_), _, _ = I._site_knots(sc, q.dtype)
            o, a, b = I._site_accelerations(sc, segs, s_, q, v); return a.sum() + b.sum() + o.sum()
        if kind == "matdamp":
            return model.material_damping(q, v)
        if kind == "frames":
            knots, (segs, s_), _, _ = I._site_knots(sc, q.dtype)
            r, p = sc.frames(q, segs, s_); return r.sum() + p.sum()
        if kind == "segframes":
            knots, (segs, s_), _, _ = I._site_knots(sc, q.dtype)
            fr = I._segment_frames(sc, q, knots); return sum(x.sum() for x in fr)
    return f
