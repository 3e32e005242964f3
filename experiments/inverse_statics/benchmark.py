"""Inverse statics of the paper's robot (PAC, hanging, no payload): accuracy, iterations and
time per target (single and batched), unreachable targets, and a tracked 200-waypoint path.

Reachable targets are made by forward-solving random commands (uniform within the default
command range, 0 to 67.7 mm of pull-in). Compilation is timed apart from solving.

    python experiments/inverse_statics/benchmark.py --n 1000 --batch 16 --out results.json

Results are written after every target, so a run cut short still reports what it measured.
"""

import argparse
import json
import os
import time

import jax
import numpy as np

import pacjax as pj
from pacjax import inverse

cache = os.environ.get("PACJAX_CACHE_DIR", os.path.expanduser("~/.cache/pacjax-jax"))
jax.config.update("jax_compilation_cache_dir", cache)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)

HERE = os.path.dirname(os.path.abspath(__file__))


def _tip(scene, controls):
    eq = pj.solve_equilibrium(scene, controls)
    ok = bool(eq.converged) and bool(eq.stable)
    return np.asarray(pj.tip_pose(scene, eq.q)[0]), ok


def _stats(x):
    x = np.asarray(x, float)
    if x.size == 0:
        return None
    return {
        "mean": float(np.mean(x)),
        "median": float(np.median(x)),
        "p90": float(np.percentile(x, 90)),
        "max": float(np.max(x)),
        "min": float(np.min(x)),
    }


def circle(center, radius, n):
    angle = np.linspace(0.0, 2.0 * np.pi, n)
    return np.stack(
        [
            center[0] + radius * np.cos(angle),
            center[1] + radius * np.sin(angle),
            np.full(n, center[2]),
        ],
        -1,
    )


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--n", type=int, default=1000, help="random reachable targets")
    parser.add_argument("--batch", type=int, default=16, help="targets in the batched timing")
    parser.add_argument("--unreachable", type=int, default=10)
    parser.add_argument("--waypoints", type=int, default=200)
    parser.add_argument("--budget", type=float, default=1e9, help="seconds for the single solves")
    parser.add_argument(
        "--track-rtol",
        type=float,
        default=1e-2,
        help="Levenberg-Marquardt rtol per waypoint (warm-started: a loose one is enough)",
    )
    parser.add_argument("--parts", default="single,unreachable,track,batch")
    parser.add_argument("--out", default=os.path.join(HERE, "benchmark.json"))
    args = parser.parse_args()
    parts = set(args.parts.split(","))

    # no payload, as a 0 kg tip mass: the structure of run.py's payload scenes (one compile)
    scene = pj.presets.stella2023(pj.PAC(), loads=(pj.PointMass(0.0, 2, 1.0),))
    lower, upper = inverse.default_command_range(scene)
    rng = np.random.default_rng(2023)
    report = {
        "scene": "pacjax.presets.stella2023(pj.PAC()), hanging, no payload",
        "machine": f"{os.cpu_count()} CPU cores (shared), jax {jax.__version__}",
        "reached_tol_m": 1e-4,
        "command_range_m": [float(lower[0]), float(upper[0])],
    }

    def save():
        with open(args.out, "w", encoding="utf-8") as f:
            json.dump(report, f, indent=2)

    # ------------------------------------------------------------------ single targets
    if "single" not in parts:
        args.n = 0
    t0 = time.perf_counter()
    first = _tip(scene, upper * rng.uniform(0, 1, 9))
    res = inverse.inverse_statics(scene, first[0])
    jax.block_until_ready(res)
    report["single_first_call_s (compile + solve)"] = time.perf_counter() - t0
    rows = []
    start = time.perf_counter()
    while len(rows) < args.n and time.perf_counter() - start < args.budget:
        u_true = lower + (upper - lower) * rng.uniform(0, 1, 9)
        target, ok = _tip(scene, u_true)
        if not ok:
            continue
        t = time.perf_counter()
        res = inverse.inverse_statics(scene, target)
        jax.block_until_ready(res)
        dt = time.perf_counter() - t
        rows.append(
            {
                "target": target.tolist(),
                "controls_true": u_true.tolist(),
                "controls": np.asarray(res.controls).tolist(),
                "error_m": float(res.error),
                "reached": bool(res.reached),
                "iterations": int(res.iterations),
                "starts": int(res.starts),
                "seconds": dt,
            }
        )
        if len(rows) % 10 == 0 or len(rows) == args.n:
            reached = np.array([r["reached"] for r in rows])
            report["single"] = {
                "n": len(rows),
                "fraction_reached": float(reached.mean()),
                "error_m": _stats([r["error_m"] for r in rows]),
                "iterations": _stats([r["iterations"] for r in rows]),
                "starts": _stats([r["starts"] for r in rows]),
                "seconds_per_target": _stats([r["seconds"] for r in rows]),
                "rows": rows,
            }
            save()
            print(f"{len(rows)} targets, {100 * reached.mean():.1f} % reached", flush=True)

    # ------------------------------------------------------------------ unreachable targets
    far = []
    for _ in range(args.unreachable if "unreachable" in parts else 0):
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        far.append(0.6 * direction)  # 0.6 m from the base: the robot is 0.41 m long
    t = time.perf_counter()
    flagged = []
    for target in far:
        res = inverse.inverse_statics(scene, target)
        flagged.append((bool(res.reached), float(res.error)))
    report["unreachable"] = (
        None
        if not far
        else {
            "n": len(far),
            "reported_reached": int(sum(r for r, _ in flagged)),
            "closest_error_m": _stats([e for _, e in flagged]),
            "seconds_per_target": (time.perf_counter() - t) / max(len(far), 1),
        }
    )
    save()
    print("unreachable:", report["unreachable"], flush=True)

    # ------------------------------------------------------------------ tracking
    if "track" in parts:
        path = circle((0.0, 0.0, -0.35), 0.04, args.waypoints)
        track = inverse.track(scene, path, rtol=args.track_rtol, atol=1e-8)
        jumps = np.abs(np.diff(np.asarray(track.result.controls), axis=0)).max(axis=1)
        report["track"] = {
            "waypoints": args.waypoints,
            "path": "circle of radius 40 mm at z = -0.35 m (first waypoint from random starts)",
            "rtol, atol": [args.track_rtol, 1e-8],
            "reached": int(np.sum(np.asarray(track.result.reached))),
            "max_error_m": float(np.max(np.asarray(track.result.error))),
            "seconds (compiled solver)": track.seconds,
            "waypoints_per_second": track.waypoints_per_second,
            "max_command_jump_m": track.max_command_jump,
            "median_command_jump_m": float(np.median(jumps)),
            "iterations": _stats(np.asarray(track.result.iterations)),
        }
        save()
        summary = {k: v for k, v in report["track"].items() if k != "iterations"}
        print("track:", summary, flush=True)

    # ------------------------------------------------------------------ batched
    if args.batch and "batch" in parts and rows:
        targets = np.array([r["target"] for r in rows[: args.batch]])
        t = time.perf_counter()
        out = inverse.inverse_statics_batch(scene, targets)
        jax.block_until_ready(out)
        first_s = time.perf_counter() - t
        t = time.perf_counter()
        out = inverse.inverse_statics_batch(scene, targets)
        jax.block_until_ready(out)
        warm = time.perf_counter() - t
        report["batched"] = {
            "n": len(targets),
            "first_call_s (compile + solve)": first_s,
            "warm_s": warm,
            "seconds_per_target": warm / len(targets),
            "fraction_reached": float(np.mean(np.asarray(out.reached))),
            "iterations": _stats(np.asarray(out.iterations)),
        }
        save()
        print("batched:", report["batched"], flush=True)


if __name__ == "__main__":
    main()
