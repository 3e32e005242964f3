"""Real-time factor of the full dynamics of the paper's robot after a step in commands.

Usage: python benchmarks/bench_dynamics.py [--models PAC PCC Poly2] [--duration 0.5]
       [--rtol 1e-4] [--solvers rosenbrock23 rosenbrock23-stiff kvaerno5] [--batch 64]
       [--rows-at-once N] [--reference-rtol 1e-7]
       [--reference-solver rosenbrock23] [--repeats 3] [--json out.json]

The robot (``pj.presets.stella2023``, hanging, 200 g payload) starts at rest in its equilibrium
under zero commands; at t = 0 the commands step to the demo's "section 1 bend" (40 mm on one
tendon of section 1) and the motion is simulated with the default damping (5 % on the lowest
mode). For each model and solver: compile time (first call, made before the reference run,
minus the median warm call), warm run time (median of ``--repeats``, the solvers alternated;
``rosenbrock23`` is ``simulate``'s default, the exact Jacobian held over 20 steps,
``rosenbrock23-stiff`` the stiff one every step), solver steps (accepted and rejected), the
real-time factor ``simulated time / warm wall time`` (> 1 is faster than real time), and the
largest distance of the tip from a reference run at ``--reference-rtol``
(``--reference-solver``; the same method 10^3 times tighter converges on the exact motion, and
Kvaerno5 is checked against it) over 11 save times. The batch: ``pj.simulate_batch`` of
``--batch`` step commands (each a pull of up to 40 mm on one random tendon) with its default
solver (``--rows-at-once``: rows vectorised together; default one at a time on a CPU, a
thread a core side by side), its aggregate real-time factor ``batch * simulated time / warm wall
time``. Nothing is asserted.
"""

import argparse
import json
import os
import platform
import statistics
import time

import jax
import numpy as np

import pacjax as pj

STEP = np.array([0.04, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
MODELS = {"PAC": pj.PAC, "PCC": pj.PCC, "Poly2": lambda: pj.PolynomialCurvature(2)}
SOLVERS = {
    "rosenbrock23": pj.dynamics.rosenbrock23,
    "rosenbrock23-stiff": lambda: pj.dynamics.rosenbrock23("stiff"),
    "kvaerno5": pj.dynamics.kvaerno5,
}


def _time(fn):
    t = time.perf_counter()
    out = fn()
    jax.block_until_ready(out)
    return time.perf_counter() - t, out


def _tips(scene, traj) -> np.ndarray:
    q = np.asarray(traj.q)
    return np.stack([np.asarray(pj.tip_pose(scene, qk)[0]) for qk in q.reshape(-1, q.shape[-1])])


def _batch_commands(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    commands = np.zeros((n, 9))
    commands[np.arange(n), rng.integers(0, 9, n)] = rng.uniform(0.01, 0.04, n)
    return commands


def run_model(model: str, args) -> dict:
    scene = pj.presets.stella2023(MODELS[model](), tip_mass=0.2)
    start = pj.solve_equilibrium(scene, np.zeros(scene.n_tendons))
    end = pj.solve_equilibrium(scene, STEP)
    damping = pj.Damping.modal(scene)
    saveat = np.linspace(0.0, args.duration, 11)

    def simulate(solver: str, rtol: float):
        return pj.simulate(
            scene,
            (0.0, args.duration),
            STEP,
            q0=start.q,
            saveat=saveat,
            damping=damping,
            solver=SOLVERS[solver](),
            rtol=rtol,
            atol=rtol * 1e-2,
            max_steps=args.max_steps,
        )

    # The measured solvers' first calls come before the reference's: a reference with the same
    # solver would otherwise have traced most of their program, and "compile" would leave out
    # what a user's first call pays.
    first, warm, last = {}, {s: [] for s in args.solvers}, {}
    for solver in args.solvers:
        first[solver], last[solver] = _time(lambda s=solver: simulate(s, args.rtol))
    wall, ref = _time(lambda: simulate(args.reference_solver, args.reference_rtol))
    ref_tips = _tips(scene, ref)
    out = {
        "model": model,
        "reference": {
            "solver": args.reference_solver,
            "rtol": args.reference_rtol,
            "steps": int(ref.num_steps),
            "wall_s": wall,
        },
        "tip_distance_to_final_equilibrium_mm": 1e3
        * float(np.linalg.norm(ref_tips[-1] - np.asarray(pj.tip_pose(scene, end.q)[0]))),
    }
    for _ in range(args.repeats):
        for solver in args.solvers:
            wall, last[solver] = _time(lambda s=solver: simulate(s, args.rtol))
            warm[solver].append(wall)
    for solver in args.solvers:
        median = statistics.median(warm[solver])
        traj = last[solver]
        out[solver] = {
            "successful": bool(traj.successful),
            "steps": int(traj.num_steps),
            "accepted_steps": int(traj.num_accepted_steps),
            "compile_s": max(first[solver] - median, 0.0),
            "warm_wall_s": median,
            "real_time_factor": args.duration / median,
            "max_tip_error_mm": 1e3
            * float(np.max(np.linalg.norm(_tips(scene, traj) - ref_tips, axis=1))),
        }
    if args.batch:
        commands = _batch_commands(args.batch)

        def batch():
            return pj.simulate_batch(
                scene,
                (0.0, args.duration),
                commands,
                start.q,
                saveat=[args.duration],
                damping=damping,
                rtol=args.rtol,
                atol=args.rtol * 1e-2,
                max_steps=args.max_steps,
                rows_at_once=args.rows_at_once,
            )

        first_b, traj = _time(batch)
        warm_b = statistics.median(_time(batch)[0] for _ in range(max(args.repeats - 1, 1)))
        out["batch"] = {
            "rows": args.batch,
            "solver": "default",
            "rows_at_once": args.rows_at_once,
            "successful_rows": int(np.sum(np.asarray(traj.successful))),
            "max_steps_per_row": int(np.max(traj.num_steps)),
            "median_steps_per_row": float(np.median(traj.num_steps)),
            "compile_s": max(first_b - warm_b, 0.0),
            "warm_wall_s": warm_b,
            "aggregate_real_time_factor": args.batch * args.duration / warm_b,
        }
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", nargs="+", default=["PAC"], choices=tuple(MODELS))
    parser.add_argument("--solvers", nargs="+", default=list(SOLVERS), choices=tuple(SOLVERS))
    parser.add_argument("--duration", type=float, default=0.5)
    parser.add_argument("--rtol", type=float, default=1e-4)
    parser.add_argument("--reference-rtol", type=float, default=1e-7)
    parser.add_argument("--reference-solver", default="rosenbrock23", choices=tuple(SOLVERS))
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--rows-at-once", type=int, default=None)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--max-steps", type=int, default=200_000)
    parser.add_argument("--json")
    args = parser.parse_args()
    result = {
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cpus",
        "jax_backend": jax.default_backend(),
        "devices": [str(d) for d in jax.devices()],
        "duration_s": args.duration,
        "rtol": args.rtol,
        "models": [],
    }
    for model in args.models:
        result["models"].append(run_model(model, args))
        print(json.dumps(result["models"][-1], indent=2), flush=True)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(result, f, indent=2)


if __name__ == "__main__":
    main()
