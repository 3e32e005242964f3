"""What a first run pays for before any solve: the command line answers without importing JAX,
``import pacjax`` leaves JAX unimported yet float64, and the persistent compilation cache is
keyed by jaxlib and processor and survives a damaged entry. Each case runs in a fresh
interpreter, since the process running the tests has long imported JAX."""

import json
import os
import subprocess
import sys
import textwrap

import jax
import pytest

from pacjax import _cache


def _python(code: str, env_update: dict | None = None, timeout: float = 300) -> dict:
    """Run ``code`` in a fresh interpreter; its last line of output, as JSON."""
    env = {k: v for k, v in os.environ.items() if k not in ("JAX_ENABLE_X64", "PACJAX_NO_X64")}
    env.update(env_update or {})
    out = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1]) | {"stderr": out.stderr}


def test_help_and_usage_errors_do_not_import_jax():
    out = _python(
        """
        import json, sys
        from pacjax.cli.main import cli
        codes = []
        for args in (["--help"], ["solve", "--help"], ["solve", "--bogus"], ["batch", "x.toml"]):
            try:
                cli.main(args, prog_name="pacjax", standalone_mode=True)
            except SystemExit as stop:
                codes.append(stop.code)
        print(json.dumps({"codes": codes, "jax": "jax" in sys.modules}))
        """
    )
    assert out["codes"] == [0, 0, 2, 2]
    assert not out["jax"]


@pytest.mark.slow  # a fresh Python process that compiles a solve (27 s): CI's slow step
def test_a_solver_first_used_inside_the_users_jit_runs():
    """pacjax loads its modules on first use, so the solver's module may first be imported
    while the user's ``jit`` traces: its compile options (top-level calls only) must still be
    left out of that nested call (they raised "compiler_options can only be passed to
    top-level jax.jit")."""
    out = _python(
        """
        import json
        import equinox as eqx
        import jax.numpy as jnp
        import pacjax as pj
        scene = pj.presets.stella2023(pj.PAC())
        solve = eqx.filter_jit(lambda sc, u: pj.solve_equilibrium(sc, u).converged)
        print(json.dumps({"converged": bool(solve(scene, jnp.full(9, 0.01)))}))
        """
    )
    assert out["converged"]


def test_import_leaves_jax_unimported_and_float64_on():
    """Arrays made after ``import pacjax`` but before any pacjax name is used are float64, and
    the ``JAX_ENABLE_X64`` that asked JAX for it is gone once a pacjax name is used."""
    out = _python(
        """
        import json, os, sys
        import pacjax
        imported = "jax" in sys.modules
        import jax.numpy as jnp
        dtype = str(jnp.zeros(1).dtype)
        pacjax.Scene
        print(json.dumps({"imported": imported, "dtype": dtype,
                          "env": os.environ.get("JAX_ENABLE_X64")}))
        """
    )
    assert (out["imported"], out["dtype"], out["env"]) == (False, "float64", None)


def test_import_restores_a_users_jax_enable_x64():
    out = _python(
        """
        import json, os
        import pacjax as pj
        scene = pj.presets.stella2023(pj.PCC(), n_sections=1, quadrature_points=4)
        import jax
        print(json.dumps({"x64": jax.config.jax_enable_x64,
                          "env": os.environ.get("JAX_ENABLE_X64")}))
        """,
        {"JAX_ENABLE_X64": "0"},
    )
    assert out["x64"] is True and out["env"] == "0"


def test_cache_directory_is_keyed_by_jaxlib_and_processor(tmp_path):
    directory = _cache.cache_directory(tmp_path)
    assert directory.parent == tmp_path
    assert directory.name.startswith(f"jaxlib-{jax.lib.__version__}-")
    assert directory.name.endswith(_cache.processor_id())
    assert len(_cache.processor_id()) == 12
    with pytest.raises(ValueError, match="min_compile_time_s"):
        _cache.enable_compilation_cache(tmp_path, min_compile_time_s=-1.0)


SOLVE_WITH_CACHE = """
import json, os
import numpy as np
import pacjax as pj
import jax

hits = []
jax.monitoring.register_event_listener(
    lambda event, **kw: hits.append(event) if event.endswith("cache_hits") else None
)
directory = pj.enable_compilation_cache(os.environ["CACHE_ROOT"], min_compile_time_s=0.0)
scene = pj.presets.stella2023(pj.PCC(), n_sections=1, quadrature_points=4)
eq = pj.solve_equilibrium(scene, np.array([0.01, 0.0, 0.0]))
print(json.dumps({"directory": str(directory), "hits": len(hits),
                  "q": np.asarray(eq.q).tolist(), "converged": bool(eq.converged)}))
"""


def _solve_with_cache(root) -> dict:
    return _python(SOLVE_WITH_CACHE, {"CACHE_ROOT": str(root)})


@pytest.mark.slow  # three fresh Python processes, two of them compiling (30 s): CI's slow step
def test_cache_is_written_read_back_and_survives_a_damaged_entry(tmp_path):
    first = _solve_with_cache(tmp_path)
    entries = sorted(p for p in os.listdir(first["directory"]) if "solve_and_sag" in p)
    assert first["converged"] and entries, os.listdir(first["directory"])
    second = _solve_with_cache(tmp_path)
    assert second["hits"] > 0 and second["q"] == first["q"]

    # A truncated entry (a process killed while writing it) is a warning and a new compile.
    path = os.path.join(first["directory"], entries[0])
    with open(path, "r+b") as f:
        f.truncate(os.path.getsize(path) // 2)
    third = _solve_with_cache(tmp_path)
    assert third["q"] == first["q"]
    assert "Error reading persistent compilation cache entry" in third["stderr"]
