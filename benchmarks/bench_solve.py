"""Single and batched equilibrium solves of the paper's robot: compile time apart from run time.

Usage: python benchmarks/bench_solve.py [--batch 100] [--repeats 3] [--json out.json]

For each strain model: compile time (first call minus a warm call), warm single-solve time,
steps, and equilibria per second for a batch of random commands (0-20 mm pull-ins, 200 g
payload), with the fraction converged and stable. Ratios are against PCC measured in the same
run. Timings are wall-clock on this machine; nothing here is asserted.

``pacjax bench`` (:mod:`pacjax.cli.bench`) extends this: float32, several batch sizes, the
plain-flow
baseline and the gradient cost, to JSON and Markdown. The models and the timer are shared.
"""

import argparse
import json
import platform

import jax
import numpy as np

import pacjax as pj
from pacjax.cli.bench import MODELS
from pacjax.cli.bench import timed as _time


def run(batch: int, repeats: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    commands = rng.uniform(0.0, 0.02, (batch, 9))
    results = {}
    for name, make in MODELS.items():
        scene = pj.presets.stella2023(make(), tip_mass=0.2)
        first, _ = _time(lambda s=scene: pj.solve_equilibrium(s, commands[0]).q)
        warm = []
        steps = []
        for u in commands[1 : 1 + repeats]:
            dt, eq = _time(lambda s=scene, u=u: pj.solve_equilibrium(s, u))
            warm.append(dt)
            steps.append(int(eq.steps))
        compile_batch, _ = _time(
            lambda s=scene: pj.solve_batch(s, commands[:2], chunk_size=batch).q
        )
        run_batch, eqs = _time(lambda s=scene: pj.solve_batch(s, commands, chunk_size=batch))
        results[name] = {
            "single_compile_s": first - float(np.median(warm)),
            "single_warm_ms": 1e3 * float(np.median(warm)),
            "single_steps_median": float(np.median(steps)),
            "batch": batch,
            "batch_compile_and_run_2_s": compile_batch,
            "batch_run_s": run_batch,
            "equilibria_per_s": batch / run_batch,
            "converged": float(np.mean(eqs.converged)),
            "stable": float(np.mean(eqs.stable)),
            "max_residual": float(np.max(eqs.residual_norm)),
        }
    base = results["PCC"]["equilibria_per_s"]
    for r in results.values():
        r["rate_vs_PCC"] = r["equilibria_per_s"] / base
    return results


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--batch", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    results = run(args.batch, args.repeats)
    print(
        f"# pacjax equilibrium solves on {platform.processor() or platform.machine()}, "
        f"{jax.devices()[0].device_kind}, jax {jax.__version__}"
    )
    print("| model | compile (s) | warm (ms) | steps | batch eq/s | vs PCC | conv. | stable |")
    print("|---|---|---|---|---|---|---|---|")
    for name, r in results.items():
        print(
            f"| {name} | {r['single_compile_s']:.1f} | {r['single_warm_ms']:.0f} | "
            f"{r['single_steps_median']:.0f} | {r['equilibria_per_s']:.1f} | "
            f"{r['rate_vs_PCC']:.2f} | {r['converged']:.0%} | {r['stable']:.0%} |"
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)


if __name__ == "__main__":
    main()
