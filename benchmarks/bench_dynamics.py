"""Real-time factor of the full dynamics of the paper's robot after a step in commands.

Usage: python benchmarks/bench_dynamics.py [--model PAC] [--duration 0.5] [--solver Kvaerno5]
       [--json out.json]

The robot (``pj.presets.stella2023``, hanging, 200 g payload) starts at rest in its equilibrium
under zero commands; at t = 0 the commands step to the demo's "section 1 bend" (40 mm on one
tendon of section 1) and the motion is simulated with the default damping (5 % on the lowest
mode). Reports compile time (first call minus a warm call) apart from the warm run time, the
number of solver steps, and the real-time factor ``simulated time / warm wall time`` (> 1 is
faster than real time). Nothing is asserted.
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


def run(model: str, duration: float, solver: str, rtol: float, max_steps: int) -> dict:
    scene = pj.presets.stella2023(MODELS[model](), tip_mass=0.2)
    start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
    end = pj.solve_equilibrium(scene, STEP)
    damping = pj.Damping.modal(scene)
    freqs = np.asarray(pj.dynamics.natural_frequencies(scene, end.q, STEP))

    def sim():
        return pj.simulate(
            scene,
            (0.0, duration),
            STEP,
            q0=start.q,
            saveat=np.linspace(0.0, duration, 51),
            damping=damping,
            solver=getattr(diffrax, solver)(),
            rtol=rtol,
            atol=rtol * 1e-2,
            max_steps=max_steps,
        )

    first, _ = _time(sim)
    warm, traj = _time(sim)
    tip_end = np.asarray(pj.tip_pose(scene, end.q)[0])
    tip_sim = np.asarray(pj.tip_pose(scene, traj.q[-1])[0])
    return {
        "model": model,
        "solver": solver,
        "rtol": rtol,
        "duration_s": duration,
        "success": bool(traj.success),
        "steps": int(traj.num_steps),
        "accepted_steps": int(traj.num_accepted_steps),
        "compile_s": max(first - warm, 0.0),
        "warm_wall_s": warm,
        "real_time_factor": duration / warm,
        "lowest_frequency_hz": float(freqs[0]),
        "highest_frequency_hz": float(freqs[-1]),
        "damping_beta_s": float(damping.stiffness),
        "tip_distance_to_final_equilibrium_mm": 1e3 * float(np.linalg.norm(tip_sim - tip_end)),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="PAC", choices=tuple(MODELS))
    parser.add_argument("--duration", type=float, default=0.5)
    parser.add_argument("--solver", default="Kvaerno5")
    parser.add_argument("--rtol", type=float, default=1e-6)
    parser.add_argument("--max-steps", type=int, default=100_000)
    parser.add_argument("--json")
    args = parser.parse_args()
    result = run(args.model, args.duration, args.solver, args.rtol, args.max_steps)
    result["machine"] = f"{platform.processor() or platform.machine()}, {os.cpu_count()} cpus"
    result["jax_backend"] = jax.default_backend()
    for key, value in result.items():
        print(f"{key:40s} {value}")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(result, f, indent=2)


if __name__ == "__main__":
    main()
