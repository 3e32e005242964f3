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
- XLA:CPU runs its Eigen kernels single-threaded (``--xla_cpu_multi_thread_eigen=false`` is
  added to ``XLA_FLAGS`` unless that flag is already there). On a 2-core machine the batched
  solve of the paper's robot under a follower force (the synthetic data of
  ``experiments/paper_study``) hung with every thread waiting, 3 times out of 3, inside the
  first compiled call; with the flag it finished in 70 s, 2 times out of 2. pacjax's matrices
  are small (tens of rows), so the threads gained nothing measurable: PAC at batch 512, 116-143
  equilibria/s either way on the same loaded 2 cores. XLA reads the flag when its CPU backend
  starts, so it only takes effect when pacjax is imported before JAX has run anything; a
  warning says so otherwise.
"""

import os
import warnings

import jax
from jax._src import xla_bridge

_EIGEN_FLAG = "--xla_cpu_multi_thread_eigen"
if _EIGEN_FLAG not in os.environ.get("XLA_FLAGS", ""):
    if xla_bridge.backends_are_initialized():
        warnings.warn(
            "pacjax was imported after JAX started its backends, so XLA:CPU keeps multi-threaded "
            f"Eigen kernels, which hung on 2-core machines; import pacjax first or set "
            f"XLA_FLAGS={_EIGEN_FLAG}=false",
            RuntimeWarning,
            stacklevel=2,
        )
    else:
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {_EIGEN_FLAG}=false".strip()

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_default_matmul_precision", "highest")
