import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
import pacjax as pj
from pacjax._model import inertia as I
from pacjax._dynamics.simulate import prepare
scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
sc, damping, *_ = prepare(scene, 0.0, 0.5, np.array([0.0, 0.5]), pj.Damping.modal(scene), None, 1e-4, 1e-6, 10000, False, I.PHI_INERTIA_FACTOR, None)
plan = sc.energy_plan()
km = I._knot_masses(sc, jnp.float64)
print(plan.knots.s.shape, km.knots.s.shape)
print(np.abs(plan.knots.s - km.knots.s).max() if plan.knots.s.shape == km.knots.s.shape else (plan.knots.s, km.knots.s))
print(plan.load_rows, sc.segment_inputs.__doc__)
