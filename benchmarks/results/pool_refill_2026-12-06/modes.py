import numpy as np, jax, jax.numpy as jnp
import pacjax as pj
from pacjax._dynamics import simulate as S
from pacjax._dynamics.equations import EquationsOfMotion, vector_field
from jax.flatten_util import ravel_pytree
STEP = np.array([0.04,0,0,0,0,0,0,0,0.])
scene0 = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
end = pj.solve_equilibrium(scene0, STEP)
damping = pj.Damping.modal(scene0)
print(damping)
scene, damping2, opts, span, ts = S.prepare(scene0, 0., .5, None, damping, None, 1e-4, 1e-6, 100000, False, S.PHI_INERTIA_FACTOR, None)
model = EquationsOfMotion.build(scene, damping2, opts.phi_inertia, jnp.float64)
args = (model, jnp.asarray(STEP))
x0, unr = ravel_pytree((end.q, jnp.zeros_like(end.q)))
f = lambda x: ravel_pytree(vector_field(0., unr(x), args))[0]
print("residual", np.abs(f(x0)).max())
J = np.asarray(jax.jacfwd(f)(x0))
ev, V = np.linalg.eig(J)
o = np.argsort(np.abs(ev))
for i in o:
    l = ev[i]; w = abs(l); z = -l.real/w if w>0 else 0
    v = np.abs(V[:12, i]); 
    print(f"{l.real:12.4g} {l.imag:+12.4g}i |l|={w:10.4g} f={w/2/np.pi:8.3g}Hz zeta={z:6.3f}  dom={np.argsort(-v)[:3]}")
