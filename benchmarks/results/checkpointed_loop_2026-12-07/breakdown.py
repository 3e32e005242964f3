"""One Rosenbrock23 step, each form of the step's loop, with a held Jacobian (no fresh one), jitted, alone and vmap-ped over 64
rows: us a step. Run with the checkout to measure first on PYTHONPATH."""
import os, sys, time, statistics
import numpy as np, jax, jax.numpy as jnp, diffrax
import pacjax as pj
from pacjax._dynamics import simulate as S
from pacjax._dynamics.equations import EquationsOfMotion, vector_field
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
damping = pj.Damping.modal(scene)
controls = S.check_simulation_controls(scene, np.array([0.04] + [0.0] * 8), 0.0, jnp.float64)
sc, damping, opts, span, ts = S.prepare(scene, 0.0, 0.5, np.linspace(0, .5, 11), damping, None, 1e-4, 1e-6, 100000, False, S.PHI_INERTIA_FACTOR, None)
model = EquationsOfMotion.build(sc, damping, opts.phi_inertia, jnp.float64)
base = S.rosenbrock23()
import dataclasses
solvers = {k: dataclasses.replace(base, autonomous=True, loop=k) for k in ("scan", "checkpointed", "lax")}
term = diffrax.ODETerm(vector_field)
args = (model, controls)
q0 = jnp.asarray(start.q); y0 = (q0, jnp.zeros_like(q0))
n = 2 * q0.size
state = (vector_field(0.0, y0, args), jnp.eye(n) * -10.0, jnp.asarray(0, jnp.int32), jnp.asarray(True))
rows = 64
ys = jax.tree.map(lambda a: jnp.broadcast_to(a, (rows,) + a.shape) * (1 + 1e-3 * jnp.arange(rows).reshape((rows,) + (1,) * a.ndim)), y0)
sts = jax.tree.map(lambda a: jnp.broadcast_to(a, (rows,) + a.shape), state)
def timeit(fn, *a, reps):
    jax.block_until_ready(fn(*a)); out = []
    for _ in range(5):
        t = time.perf_counter()
        for _ in range(reps): r = fn(*a)
        jax.block_until_ready(r); out.append((time.perf_counter() - t) / reps * 1e6)
    return statistics.median(out)
vf1 = jax.jit(lambda y: vector_field(0.0, y, args))
vfm = jax.jit(jax.vmap(lambda y: vector_field(0.0, y, args)))
solver = solvers["checkpointed"]
fresh_state = state[:2] + (jnp.asarray(100, jnp.int32), state[3])
fresh_sts = jax.tree.map(lambda a: jnp.broadcast_to(a, (rows,) + a.shape), fresh_state)
one = jax.jit(lambda y, st: solver.step(term, 0.0, 1e-4, y, args, st, False)[0])
many = jax.jit(jax.vmap(lambda y, st: solver.step(term, 0.0, 1e-4, y, args, st, False)[0]))
print(pj.__file__, flush=True)
for rnd in range(3):
    print(rnd, "vf one us", round(timeit(vf1, y0, reps=500), 1), "vf 64 us/row", round(timeit(vfm, ys, reps=50) / rows, 1), flush=True)
    print(rnd, "held step one us", round(timeit(one, y0, state, reps=200), 1), "64 us/row", round(timeit(many, ys, sts, reps=10) / rows, 1), flush=True)
    print(rnd, "fresh step one us", round(timeit(one, y0, fresh_state, reps=50), 1), "64 us/row", round(timeit(many, ys, fresh_sts, reps=3) / rows, 1), flush=True)
