"""What importing pacjax sets in JAX (see pacjax/_config.py)."""

import jax
import jax.numpy as jnp

import pacjax  # noqa: F401


def test_float64_is_on():
    assert jax.config.jax_enable_x64
    assert jnp.zeros(1).dtype == jnp.float64


def test_float32_products_are_not_rounded_to_tf32():
    # JAX's GPU default (TensorFloat-32 inputs) left 0 % of the paper robot's float32 equilibria
    # converged on an H100; pacjax asks for full float32 products everywhere.
    assert jax.config.jax_default_matmul_precision in ("highest", "float32")
