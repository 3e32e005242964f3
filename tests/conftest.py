"""Shared test set-up: float64, a persistent compilation cache for the suite, and freeing
compiled code between modules."""

import collections
import gc
import os
import pathlib

# Before JAX starts: a worker of a parallel run (pytest-xdist) shares the accelerator with the
# others, so none may take most of its memory up front.
if "PYTEST_XDIST_WORKER" in os.environ:
    os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

import jax  # noqa: E402
import pytest  # noqa: E402

import pacjax  # noqa: E402, F401  (switches on float64)
from pacjax import _cache  # noqa: E402

# Compiled programs are kept on disk in the checkout (pacjax's cache: a folder per jaxlib and
# processor, so that nothing compiled elsewhere is read): test modules, parallel workers and
# CI's two steps that solve the same scene structures load them instead of compiling again.
# PACJAX_CACHE_DIR=DIR moves it, PACJAX_CACHE_DIR=off turns it off. The command line, invoked
# in-process by the CLI tests, reads the same variable.
os.environ.setdefault(
    "PACJAX_CACHE_DIR", str(pathlib.Path(__file__).resolve().parent.parent / ".pytest-jax-cache")
)
_cache.enable_from_environment()
# Traced programs are not stored (pacjax._stored): tests replace pacjax's functions at run time
# and clear JAX's caches to trace them again, which a stored trace would not see.
os.environ.setdefault("PACJAX_STORED_PROGRAMS", "0")


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_code():
    """Free every compiled executable when a test module ends.

    A module compiles its own scenes' solvers; kept until the end of the run they grew the
    pytest process past 5 GB, and a later large compilation (the Hessian of the kinematics)
    aborted inside XLA in CI's slow step. Modules sharing a scene structure load it again from
    the compilation cache.
    """
    yield
    jax.clear_caches()
    gc.collect()


@pytest.hookimpl(trylast=True)  # after the -m selection: weigh only the tests that will run
def pytest_collection_modifyitems(config, items):
    """Longest files first. With ``--no-loadscope-reorder`` (CI's slow step) a parallel run
    hands out whole files in collection order; a study of minutes left for the end keeps one
    worker busy while the others idle. A file's weight is the sum of its tests'
    ``long(minutes=...)`` estimates (minutes on 2 cores, for this ordering only). Without it
    (the default step, many short files) pytest-xdist hands out the files with most tests
    first."""
    weight = collections.Counter()
    for item in items:
        mark = item.get_closest_marker("long")
        if mark is not None:
            weight[item.path] += mark.kwargs.get("minutes", 1.0)
    items.sort(key=lambda item: -weight[item.path])
