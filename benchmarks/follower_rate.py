"""Equilibria per second of the paper's robot under the 3.41 N tip follower force, against the
same robot with a 200 g tip mass measured in the same run (warm ``solve_batch``, compile apart).

Usage: python benchmarks/follower_rate.py [--model PAC] [--batch 10000] [--json out.json]

The follower scene is the one of ``experiments/error_vs_runtime`` (non-conservative: the step
descends the residual norm, and a failed row is retried by load continuation). Nothing here is
asserted; timings are wall-clock on this machine.
"""

import argparse
import json
import platform
import sys
from pathlib import Path

import jax
import numpy as np

import pacjax as pj
from pacjax.cli.bench import MODELS
from pacjax.cli.bench import timed as _time

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments" / "error_vs_runtime"))
import study  # noqa: E402


def scene_for(model: str, load: str) -> pj.Scene:
    if load == "mass":
        return pj.presets.stella2023(MODELS[model](), tip_mass=0.2)
    return study.scene_for(dict(model=model, quadrature=8, dtype="float64", tol=1e-10), load)


def run(model: str, batch: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    first_u, warm_u = rng.uniform(0.0, 0.02, (2, batch, 9))
    out = {}
    for load in ("mass", "follower"):
        scene = scene_for(model, load)

        def solve(u, scene=scene):
            eq = pj.solve_batch(scene, u, chunk_size=batch, progress=False)
            jax.block_until_ready(eq.q)
            return eq

        first, _ = _time(lambda: solve(first_u))
        warm, eq = _time(lambda: solve(warm_u))
        steps = np.asarray(eq.steps)
        out[load] = {
            "first_call_s": first,
            "warm_s": warm,
            "equilibria_per_s": batch / warm,
            "steps_mean": float(steps.mean()),
            "steps_max": int(steps.max()),
            "converged": float(np.mean(eq.converged)),
            "stable": float(np.mean(eq.stable)),
        }
        print(load, json.dumps(out[load]), flush=True)
    out["follower_over_mass_time"] = (
        out["mass"]["equilibria_per_s"] / out["follower"]["equilibria_per_s"]
    )
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="PAC", choices=list(MODELS))
    parser.add_argument("--batch", type=int, default=10_000)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    record = {
        "model": args.model,
        "batch": args.batch,
        "machine": platform.processor() or platform.machine(),
        "devices": [str(d) for d in jax.devices()],
        "jax": jax.__version__,
        **run(args.model, args.batch),
    }
    print(json.dumps(record, indent=2))
    if args.json:
        args.json.write_text(json.dumps(record, indent=2))


if __name__ == "__main__":
    main()
