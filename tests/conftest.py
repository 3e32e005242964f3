"""Shared test set-up: float64, an opt-in persistent compilation cache, and shared scenes."""

import gc
import os

import jax
import pytest

import pacjax  # noqa: F401  (switches on float64)

# Opt-in only (`PACJAX_CACHE_DIR=~/.cache/pacjax-jax pytest`): re-runs on a developer's machine
# then reuse compiled solvers. CI leaves it off: loading a cached XLA:CPU executable written by
# an earlier pytest process aborted the CI's slow step (SIGABRT inside
# compilation_cache.get_executable_and_time), and a fresh CI checkout gains nothing from it.
# The CLI, invoked in-process by the CLI tests, reads the same variable: "off" keeps it off too.
_cache = os.environ.setdefault("PACJAX_CACHE_DIR", "off")
if _cache.lower() not in ("", "off", "none", "0"):
    jax.config.update("jax_compilation_cache_dir", os.path.expanduser(_cache))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_code():
    """Free every compiled executable when a test module ends.

    A module compiles its own scenes' solvers; kept until the end of the run they grew the
    pytest process past 5 GB, and a later large compilation (the Hessian of the kinematics)
    aborted inside XLA in CI's slow step. Modules sharing a scene structure recompile it.
    """
    yield
    jax.clear_caches()
    gc.collect()
