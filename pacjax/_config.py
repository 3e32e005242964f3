"""Numerical configuration applied when pacjax is imported.

pacjax solves and fits in float64 by default (SPEC section 4), so double precision is switched
on for JAX here. Float32 work (batch throughput) is explicit: cast the scene and controls with
:func:`pacjax.astype`.
"""

import jax

jax.config.update("jax_enable_x64", True)
