# One vector field of the paper's robot (PAC) as simulate builds it: flops, bytes, us a row at w rows.
import os, time
import numpy as np, jax, jax.numpy as jnp
import pacjax as pj
from pacjax._dynamics.simulate import prepare, default_solver
from pacjax._dynamics.equations import EquationsOfMotion, vector_field
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
sc, dm, opts, span, ts = prepare(scene, 0.0, 0.5, [0.5], damping, default_solver(1e-4), 1e-4, 1e-6, 100000, False, 1e-6, None)
model = EquationsOfMotion.build(sc, dm, 1e-6, jnp.float64)
n = scene.n_dofs; rng = np.random.default_rng(0)
u0 = jnp.asarray(np.array([0.04] + [0.0]*8))
f = lambda q, v: vector_field(0.0, (q, v), (model, u0))[1]
out = [os.environ.get("TAG", ""), pj.__file__.split("/")[2], str(getattr(sc, "knot_grid", None))]
for w in (1, 16):
    q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((w, n)))
    v = jnp.asarray(0.1 * rng.standard_normal((w, n)))
    c = jax.jit(jax.vmap(f)).lower(q, v).compile()
    ca = c.cost_analysis(); ca = ca[0] if isinstance(ca, list) else ca
    jax.block_until_ready(c(q, v)); t_ = []
    for r in range(7):
        t = time.perf_counter()
        for _ in range(30): o = c(q, v)
        jax.block_until_ready(o); t_.append((time.perf_counter() - t) / 30)
    out.append(f"w{w}: {ca.get('flops',0)/w:.0f} flops, {ca.get('bytes accessed',0)/w:.0f} B, {np.median(t_)/w*1e6:.1f} us a row")
print(" | ".join(out), flush=True)
