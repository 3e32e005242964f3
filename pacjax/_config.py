"""Numerical configuration.

- pacjax solves and fits in float64 by default (SPEC section 4), so importing pacjax switches
  on JAX's ``jax_enable_x64`` for the process (see :mod:`pacjax._x64`): without it JAX has no
  float64 arrays. Set the environment variable ``PACJAX_NO_X64=1`` before the import to leave
  JAX as it is (everything then runs in float32; cast scenes with :func:`pacjax.astype` for a
  float32 batch either way). Importing pacjax changes no other JAX setting.
- Every matrix product of the model and the solvers asks for full precision
  (:data:`MATMUL_PRECISION` on the call). JAX's default on NVIDIA GPUs since Ampere rounds the
  inputs of a float32 product to TensorFloat-32 (10-bit mantissa, about 1e-3 relative); the
  kinematics chains rotations as 3x3 products, so a float32 residual would then carry errors
  above float32's solver tolerance. Float64 products and CPUs are unaffected.
"""

import jax

from . import _x64

#: Precision of every matrix product in pacjax (``precision=`` of ``jnp.einsum`` and the like).
MATMUL_PRECISION = jax.lax.Precision.HIGHEST

#: Whether importing pacjax switched on float64 (``PACJAX_NO_X64`` unset, empty or "0").
X64 = _x64.X64

_x64.settle()
