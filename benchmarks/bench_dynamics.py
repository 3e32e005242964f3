"""Real-time factor of the full dynamics of the paper's robot after a step in commands.

Usage: python benchmarks/bench_dynamics.py [--model PAC] [--duration 0.5] [--solver NAME]
       [--baseline NAME] [--json out.json]

The robot (``pj.presets.stella2023``, hanging, 200 g payload) starts at rest in its equilibrium
under zero commands; at t = 0 the commands step to the demo's "section 1 bend" (40 mm on one
tendon of section 1) and the motion is simulated with the default damping (5 % on the lowest
mode). Reports compile time (first call minus a warm call) apart from the warm run time, the
number of solver steps, and the real-time factor ``simulated time / warm wall time`` (> 1 is
faster than real time). Nothing is asserted.

``--solver``: ``default`` (``pj.simulate``'s own: Kvaerno5 with pacjax's dense-Jacobian chord
method) or the name of a diffrax solver class. ``--baseline NAME`` runs the same simulation with
that solver too (``Kvaerno5``: diffrax's stock one) and prints the ratios of compile and warm
times against it.
"""

import argparse
import json
import os
import platform
import time

import diffrax
import jax
import numpy as np

import pacjax as pj

STEP = np.array([0.04, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
MODELS = {"PAC": pj.PAC, "PCC": pj.PCC, "Poly1": lambda: pj.PolynomialCurvature(1)}


def _time(fn):
    t = time.perf_counter()
    out = fn()
    jax.block_until_ready(out)
    return time.perf_counter() - t, out


def _simulation(scene, start, damping, duration, solver, rtol, max_steps) -> dict:
    """Time one simulation (first call and a warm one) with ``solver`` (a name)."""

    def sim():
        return pj.simulate(
            scene,
            (0.0, duration),
            STEP,
            q0=start.q,
            saveat=np.linspace(0.0, duration, 51),
            damping=damping,
            solver=None if solver == "default" else getattr(diffrax, solver)(),
            rtol=rtol,
            atol=rtol * 1e-2,
            max_steps=max_steps,
        )

    first, _ = _time(sim)
    warm, traj = _time(sim)
    return {
        "solver": solver,
        "success": bool(traj.success),
        "steps": int(traj.num_steps),
        "accepted_steps": int(traj.num_accepted_steps),
        "compile_s": max(first - warm, 0.0),
        "warm_wall_s": warm,
        "real_time_factor": duration / warm,
        "final_q": np.asarray(traj.q[-1]),
    }


def run(
    model: str,
    duration: float,
    solver: str,
    rtol: float,
    max_steps: int,
    baseline: str | None = None,
) -> dict:
    scene = pj.presets.stella2023(MODELS[model](), tip_mass=0.2)
    start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
    end = pj.solve_equilibrium(scene, STEP)
    damping = pj.Damping.modal(scene)
    freqs = np.asarray(pj.dynamics.natural_frequencies(scene, end.q, STEP))
    result = _simulation(scene, start, damping, duration, solver, rtol, max_steps)
    final_q = result.pop("final_q")
    tip_end = np.asarray(pj.tip_pose(scene, end.q)[0])
    tip_sim = np.asarray(pj.tip_pose(scene, final_q)[0])
    result = {
        "model": model,
        "rtol": rtol,
        "duration_s": duration,
        **result,
        "lowest_frequency_hz": float(freqs[0]),
        "highest_frequency_hz": float(freqs[-1]),
        "damping_beta_s": float(damping.stiffness),
        "tip_distance_to_final_equilibrium_mm": 1e3 * float(np.linalg.norm(tip_sim - tip_end)),
    }
    if baseline is not None:
        base = _simulation(scene, start, damping, duration, baseline, rtol, max_steps)
        base_q = base.pop("final_q")
        base["max_abs_q_difference"] = float(np.max(np.abs(base_q - final_q)))
        result["baseline"] = base
        result["compile_ratio_to_baseline"] = result["compile_s"] / base["compile_s"]
        result["warm_ratio_to_baseline"] = result["warm_wall_s"] / base["warm_wall_s"]
    return result


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="PAC", choices=tuple(MODELS))
    parser.add_argument("--duration", type=float, default=0.5)
    parser.add_argument("--solver", default="default")
    parser.add_argument("--baseline", help="a diffrax solver class to time too (e.g. Kvaerno5)")
    parser.add_argument("--rtol", type=float, default=1e-6)
    parser.add_argument("--max-steps", type=int, default=100_000)
    parser.add_argument("--json")
    args = parser.parse_args()
    result = run(args.model, args.duration, args.solver, args.rtol, args.max_steps, args.baseline)
    result["machine"] = f"{platform.processor() or platform.machine()}, {os.cpu_count()} cpus"
    result["jax_backend"] = jax.default_backend()
    for key, value in result.items():
        print(f"{key:40s} {value}")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(result, f, indent=2)


if __name__ == "__main__":
    main()
