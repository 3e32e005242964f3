"""Numerical configuration applied when pacjax is imported.

- pacjax solves and fits in float64 by default (SPEC section 4), so double precision is switched
  on for JAX here. Float32 work (batch throughput) is explicit: cast the scene and controls with
  :func:`pacjax.astype`.
- Matrix products run at full float32 precision on every backend. JAX's default on NVIDIA GPUs
  since Ampere rounds the inputs of a float32 product to TensorFloat-32 (10-bit mantissa, about
  1e-3 relative); the kinematics chains rotations as 3x3 products, so a float32 residual then
  carries errors above float32's solver tolerance (measured on an H100: 0 % of 10,000 float32
  equilibria of the paper's robot converged to 1e-4, median 300 steps). CPUs are
  unaffected. Code of your own that wants TF32 back can ask for it locally with
  ``jax.default_matmul_precision("tensorfloat32")``.
"""

import jax

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_default_matmul_precision", "highest")
