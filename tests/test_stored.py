"""Traced programs kept on disk (:mod:`pacjax._stored`): a later process loads them without
tracing, gets the same result, and a damaged or unkeyable call still runs."""

import json
import os
import subprocess
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pacjax as pj
from pacjax import _stored

TRACES = []


class _Scale(eqx.Module):
    factor: float = eqx.field(static=True)
    offset: jnp.ndarray


def _affine(module, x, *, power=1):
    TRACES.append(x.shape)  # runs while tracing only
    return {"y": module.factor * x**power + module.offset, "label": "affine"}


@pytest.fixture
def store(tmp_path, monkeypatch):
    monkeypatch.setattr(_stored, "directory", lambda: tmp_path)
    monkeypatch.setattr(_stored, "MIN_TRACE_TIME_S", 0.0)
    monkeypatch.setattr(_stored, "_memo", {})
    TRACES.clear()
    return tmp_path


def _call(module, x, **kwargs):
    return _stored.call_stored(_affine, {}, (module, x), kwargs)


def test_a_stored_program_is_loaded_without_tracing(store):
    module = _Scale(2.0, jnp.array(1.0))
    x = np.arange(3.0)
    first = _call(module, x)
    assert TRACES == [(3,)] and first["label"] == "affine"
    np.testing.assert_array_equal(first["y"], 2.0 * x + 1.0)
    assert len(list(store.glob("_affine-*.bin"))) == 1
    _stored._memo.clear()  # a new process: only the disk remains
    again = _call(module, x + 1.0)
    assert TRACES == [(3,)], "the stored program was traced again"
    np.testing.assert_array_equal(again["y"], 2.0 * (x + 1.0) + 1.0)
    assert again["label"] == "affine"


def test_what_decides_the_trace_keys_the_program(store):
    x = np.arange(3.0)
    _call(_Scale(2.0, jnp.array(1.0)), x)
    _call(_Scale(3.0, jnp.array(1.0)), x)  # another static value
    _call(_Scale(2.0, jnp.array(1.0)), x.astype(np.float32))  # another dtype
    _call(_Scale(2.0, jnp.array(1.0)), x, power=2)  # another static keyword
    np.testing.assert_array_equal(_call(_Scale(2.0, jnp.array(1.0)), x, power=2)["y"], 2 * x**2 + 1)
    assert len(TRACES) == 4 and len(list(store.glob("*.bin"))) == 4


def test_a_damaged_entry_is_skipped_with_a_warning_and_written_again(store):
    module, x = _Scale(2.0, jnp.array(1.0)), np.arange(3.0)
    _call(module, x)
    (path,) = store.glob("*.bin")
    path.write_bytes(path.read_bytes()[:100])
    _stored._memo.clear()
    with pytest.warns(RuntimeWarning, match="skipped the stored program"):
        out = _call(module, x)
    np.testing.assert_array_equal(out["y"], 2.0 * x + 1.0)
    _stored._memo.clear()
    np.testing.assert_array_equal(_call(module, x)["y"], 2.0 * x + 1.0)  # rewritten whole
    assert len(TRACES) == 2


def test_calls_that_cannot_be_keyed_are_not_stored(store, monkeypatch):
    x = np.arange(3.0)
    unprintable = _Scale(lambda v: v, jnp.array(1.0))  # a static value printed with an address
    assert _stored.call_stored(lambda m, v: v, {}, (unprintable, x), {}) is NotImplemented
    static_leaves, static_def = jax.tree.flatten(
        eqx.filter(unprintable, eqx.is_array, inverse=True)
    )
    assert _stored._key(_affine, {}, static_def, static_leaves, None, ()) is None
    monkeypatch.setattr(_stored, "directory", lambda: None)  # the compilation cache off
    assert _call(_Scale(2.0, jnp.array(1.0)), x) is NotImplemented
    assert not list(store.glob("*.bin"))


@pytest.mark.slow  # a new Python process that imports pacjax and compiles: CI's slow step
def test_a_solve_in_a_new_process_loads_its_program_and_agrees(tmp_path):
    """Two processes with the same cache: the second solves (one equilibrium, and a batch,
    whose rounds compile in a thread) without tracing the solver and gets the first one's
    equilibria bit for bit."""
    code = f"""
import json, jax, numpy as np, pacjax as pj
from pacjax import _stored
from pacjax._statics import equilibrium
pj.enable_compilation_cache({str(tmp_path)!r})
traced = []
solve = equilibrium.solve_core
equilibrium.solve_core = lambda *a: traced.append(1) or solve(*a)
scene = pj.presets.stella2023(pj.PolynomialCurvature(1), tip_mass=0.2)
eq = pj.solve_equilibrium(scene, np.full(scene.n_tendons, 0.004))
rows = np.random.default_rng(0).uniform(0.0, 0.01, (6, scene.n_tendons))
batch = pj.solve_batch(scene, rows, progress=False)
print(json.dumps({{"q": np.asarray(eq.q).tolist(), "traced": len(traced),
                  "ok": bool(eq.successful), "reason": eq.reason,
                  "batch": np.asarray(batch.q).tolist(),
                  "batch_ok": bool(batch.successful.all())}}))
"""
    runs = []
    for _ in range(2):
        env = {**os.environ, _stored.ENVIRONMENT: "1"}
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
        assert proc.returncode == 0, proc.stderr[-2000:]
        runs.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    assert runs[0]["ok"] and runs[1]["ok"] and runs[0]["reason"] == runs[1]["reason"]
    assert runs[1]["traced"] == 0
    assert runs[0]["q"] == runs[1]["q"] and runs[0]["batch"] == runs[1]["batch"]
    assert runs[1]["batch_ok"]
    direct = pj.solve_equilibrium(
        scene := pj.presets.stella2023(pj.PolynomialCurvature(1), tip_mass=0.2),
        np.full(scene.n_tendons, 0.004),
    )
    np.testing.assert_allclose(runs[1]["q"], direct.q, rtol=0, atol=1e-12)
