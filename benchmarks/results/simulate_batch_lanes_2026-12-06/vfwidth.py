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
        if kind == "matdamp":
            return model.material_damping(q, v)
    return f
W = [int(w) for w in sys.argv[1:]] or [1, 8, 64]
for kind in ["vf", "body", "potgrad", "tendon", "matdamp"]:
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
