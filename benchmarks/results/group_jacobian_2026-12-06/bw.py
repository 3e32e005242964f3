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
        if kind == "frames":
            knots, (segs, s_), _, _ = I._site_knots(sc, q.dtype)
            r, p = sc.frames(q, segs, s_); return r.sum() + p.sum()
        if kind == "segframes":
            knots, (segs, s_), _, _ = I._site_knots(sc, q.dtype)
            fr = I._segment_frames(sc, q, knots); return sum(x.sum() for x in fr)
    return f
W = [int(w) for w in sys.argv[1].split(",")]
for kind in sys.argv[2].split(":"):
    for w in W:
        q = jnp.asarray(np.asarray(start.q)[None] + 0.01 * rng.standard_normal((w, n)))
        v = jnp.asarray(0.1 * rng.standard_normal((w, n)))
        import os
        from pacjax._jit import CPU_COMPILE_OPTIONS
        f = jax.jit(jax.vmap(parts(kind)))
        if os.environ.get("CLASSIC", "1") == "1":
            f = f.lower(q, v).compile(compiler_options=CPU_COMPILE_OPTIONS)
        jax.block_until_ready(f(q, v))
        ts_ = []
        for r in range(5):
            t = time.perf_counter()
            for _ in range(30): out = f(q, v)
            jax.block_until_ready(out); ts_.append((time.perf_counter() - t) / 30)
        m = np.median(ts_)
        print(f"{kind:9s} width {w:3d}: {m*1e3:.3f} ms/call, {m/w*1e6:.1f} us/row", flush=True)
