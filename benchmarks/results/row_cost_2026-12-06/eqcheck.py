import numpy as np, jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
import pacjax as pj
from pacjax._model import inertia as I
rng = np.random.default_rng(1)
for model in (pj.PAC(), pj.PCC(), pj.PolynomialCurvature(2)):
    sc = pj.presets.stella2023(model, tip_mass=0.2)
    q = jnp.asarray(0.3 * rng.standard_normal(sc.n_dofs)); v = jnp.asarray(rng.standard_normal(sc.n_dofs))
    M0, b0 = jax.jit(lambda q, v: I.chained_body_dynamics(sc, q, v))(q, v)
    M1, b1 = jax.jit(lambda q, v: I.structured_body_dynamics(sc, q, v))(q, v)
    M2 = jax.jit(lambda q: I.mass_matrix(sc, q))(q)
    print(type(model).__name__, float(jnp.abs(M1 - M0).max() / jnp.abs(M0).max()), float(jnp.abs(b1 - b0).max() / jnp.abs(b0).max()), float(jnp.abs(M2 - M0).max()))
