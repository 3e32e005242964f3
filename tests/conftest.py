"""Shared test set-up: float64, a persistent compilation cache, and shared scenes."""

import os

import jax

import pacjax  # noqa: F401  (switches on float64)

# Re-runs of the suite on the same machine reuse compiled solvers.
_default_cache = os.path.join(os.path.expanduser("~"), ".cache", "pacjax-jax")
jax.config.update("jax_compilation_cache_dir", os.environ.get("PACJAX_CACHE_DIR", _default_cache))
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
