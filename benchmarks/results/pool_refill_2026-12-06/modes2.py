import numpy as np, jax, jax.numpy as jnp
import pacjax as pj
from pacjax._dynamics import simulate as S
from pacjax._dynamics.equations import EquationsOfMotion, vector_field
from jax.flatten_util import ravel_pytree
STEP = np.array([0.04,0,0,0,0,0,0,0,0.])
scene0 = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
start = pj.solve_equilibrium(scene0, np.zeros(9))
damping = pj.Damping.modal(scene0)
tr = pj.simulate(scene0, (0.0, 0.5), STEP, q0=start.q, saveat=np.linspace(0,0.5,26), damping=damping, dense=True)
np.set_printoptions(precision=3, suppress=True, linewidth=200)
print("q over time"); print(np.c_[np.asarray(tr.ts), np.asarray(tr.q)])
scene, damping2, opts, span, ts = S.prepare(scene0, 0., .5, None, damping, None, 1e-4, 1e-6, 100000, False, S.PHI_INERTIA_FACTOR, None)
model = EquationsOfMotion.build(scene, damping2, opts.phi_inertia, jnp.float64)
args = (model, jnp.asarray(STEP))
for t in [0.25, 0.35, 0.45]:
    q, qd = tr.evaluate(t)
    x0, unr = ravel_pytree((q, qd))
    f = lambda x: ravel_pytree(vector_field(0., unr(x), args))[0]
    J = np.asarray(jax.jacfwd(f)(x0))
    ev = np.linalg.eigvals(J)
    ev = ev[np.argsort(np.abs(ev))][:16]
    print(t, " ".join(f"{l.real:.3g}{l.imag:+.3g}i" for l in ev))
