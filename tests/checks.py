"""Checks shared by the test files, compiled (op by op, a scene's residual compiles hundreds of
small programs)."""

import equinox as eqx
import jax.numpy as jnp


@eqx.filter_jit
def scaled_residual(scene, q, controls=None):
    """``max |F_i| / (D_ii sigma_i)``, the residual as :class:`pacjax.Equilibrium` defines it;
    ``controls`` None: the scene's defaults."""
    controls = scene.default_controls(q.dtype) if controls is None else controls
    scale = scene.elastic_stiffness_diagonal(q.dtype) * scene.coordinate_scale(q.dtype)
    return jnp.max(jnp.abs(scene.residual(q, controls) / scale))
