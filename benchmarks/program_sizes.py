"""How big the compiled programs behind each entry point are: jaxpr equations (what tracing
walks) and lines of lowered StableHLO (what XLA compiles), on the paper's robot with PAC and a
200 g tip mass.

Usage: python benchmarks/program_sizes.py [out.json]

The programs are captured on the entry points' own first calls (the single solve's
``solve_core``, the batch's ``_advance`` and ``_start_block``, identification's ``_evaluate``,
the inverse solver's Levenberg-Marquardt ``_solve_core``) and traced again here, so they are
exactly what a user's call compiles (the single solve's program is ``solve_core`` with the ring
chords' sag at the solution, ``_solve_checked``). ``trace_s`` is that second trace (JAX reuses
the traces of inner functions, so it understates a fresh process's: ``first_run.py`` measures
those).
"""

import argparse
import json
import time

import equinox as eqx
import jax
import numpy as np

import pacjax as pj
from pacjax._identify import evaluation as identify_evaluation
from pacjax._inverse import inverse as inverse_module
from pacjax._statics import equilibrium, pool


class _Stop(Exception):
    """Raised by a capture that only wants the call's arguments."""


def count_equations(jaxpr) -> int:
    """Equations of ``jaxpr``, those of its sub-jaxprs (loop bodies, calls) included."""
    n = 0
    for eqn in jaxpr.eqns:
        n += 1
        for param in eqn.params.values():
            for sub in param if isinstance(param, (list, tuple)) else [param]:
                if isinstance(sub, jax.extend.core.ClosedJaxpr):
                    sub = sub.jaxpr
                if isinstance(sub, jax.extend.core.Jaxpr):
                    n += count_equations(sub)
    return n


def capture(module, name: str, captured: dict, stop: bool = False):
    """Replace ``module.name`` by a wrapper that records the arguments of its first call."""
    original = getattr(module, name)

    def wrapper(*args, **kwargs):
        captured.setdefault(name, (original, args, kwargs))
        if stop:
            raise _Stop
        return original(*args, **kwargs)

    setattr(module, name, wrapper)


def measure(captured: dict, name: str) -> dict:
    fn, args, kwargs = captured[name]
    inner = getattr(fn, "__wrapped__", fn)

    def call(*a):
        return inner(*a, **kwargs)

    start = time.perf_counter()
    jaxpr = eqx.filter_make_jaxpr(call)(*args)[0]
    trace_s = time.perf_counter() - start
    text = eqx.filter_jit(call).lower(*args).as_text()
    return {
        "jaxpr_equations": count_equations(jaxpr.jaxpr),
        "stablehlo_lines": text.count("\n"),
        "trace_s": round(trace_s, 2),
    }


def main(out_path: str | None = None) -> dict:
    captured: dict = {}
    capture(equilibrium, "_solve_checked", captured)
    capture(pool, "_advance", captured)
    capture(pool, "_start_block", captured)
    capture(identify_evaluation, "_evaluate", captured, stop=True)
    capture(inverse_module, "solve_one", captured, stop=True)

    scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
    rng = np.random.default_rng(2)
    eq = pj.solve_equilibrium(scene, rng.uniform(0.0, 0.02, 9))
    pj.solve_batch(scene, rng.uniform(0.0, 0.02, (100, 9)))
    dataset, _ = pj.synthetic_mocap(scene, rng.uniform(0.0, 0.02, (16, 9)), seed=0)
    try:
        pj.identify(scene, dataset, ("bending_stiffness",), max_iterations=2)
    except _Stop:
        pass
    tip, _ = pj.tip_pose(scene, eq.q)
    try:
        pj.inverse_statics(scene, np.asarray(tip))
    except _Stop:
        pass

    labels = {
        "solve: solve_core": "_solve_checked",
        "batch: _advance": "_advance",
        "batch: _start_block": "_start_block",
        "identify: _evaluate": "_evaluate",
        "inverse: _solve_core": "solve_one",
    }
    out = {}
    for label, name in labels.items():
        out[label] = measure(captured, name)
        print(label, out[label], flush=True)
    if out_path:
        with open(out_path, "w", encoding="utf-8") as f:
            json.dump(out, f, indent=1)
    return out


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", help="write the sizes to this JSON file")
    main(parser.parse_args().out)
