"""Inverse statics of the paper's robot (PAC, hanging, no payload): accuracy, iterations and
time per target (single and batched), unreachable targets, and a tracked 200-waypoint path.

Reachable targets are the tips of random commands (uniform within the default command range,
0 to 67.7 mm of pull-in), forward-solved in one batch. Starts come from a workspace of
``--workspace`` forward-solved random commands (its nearest samples to each target; built once,
timed apart; ``--workspace 0``: random starts only). Compilation is timed apart from solving.

    python experiments/inverse_statics/benchmark.py --n 1000 --n-single 1000 --out results.json

Results are written after every part (and every 10 single targets), so a run cut short still
reports what it measured.
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


def reachable_targets(scene, n, lower, upper, rng):
    """``n`` tips of random commands whose equilibria converged and are stable."""
    u = lower + (upper - lower) * rng.uniform(0, 1, (2 * n + 16, lower.size))
    eq = pj.solve_batch(scene, u, progress=False)
    ok = np.asarray(eq.converged & eq.stable)
    tips = np.asarray(jax.vmap(lambda q: pj.tip_pose(scene, q)[0])(eq.q))
    keep = np.flatnonzero(ok)[:n]
    return tips[keep], u[keep]


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
    parser.add_argument(
        "--n-single", type=int, default=1000, help="of those, solved one by one (0: none)"
    )
    parser.add_argument(
        "--batch", type=int, default=1000, help="of those, solved by inverse_statics_batch"
    )
    parser.add_argument("--chunk", type=int, default=256, help="inverse_statics_batch chunk")
    parser.add_argument(
        "--workspace", type=int, default=2048, help="workspace samples for the starts (0: none)"
    )
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
        "machine": f"{os.cpu_count()} CPU cores, jax {jax.__version__}, "
        f"{jax.devices()[0].platform} ({jax.devices()[0].device_kind})",
        "reached_tol_m": 1e-4,
        "command_range_m": [float(lower[0]), float(upper[0])],
    }

    def save():
        with open(args.out, "w", encoding="utf-8") as f:
            json.dump(report, f, indent=2)

    t = time.perf_counter()
    targets, u_true = reachable_targets(scene, args.n, lower, upper, rng)
    report["targets"] = {"n": len(targets), "seconds (compile + solve)": time.perf_counter() - t}
    workspace = None
    if args.workspace:
        t = time.perf_counter()
        workspace = inverse.sample_workspace(scene, args.workspace, seed=1)
        jax.block_until_ready(workspace.q)
        report["workspace"] = {
            "samples": args.workspace,
            "converged": float(np.mean(np.asarray(workspace.converged))),
            "seconds (compile + solve)": time.perf_counter() - t,
        }
    starts = "nearest workspace samples, then random" if workspace is not None else "random"
    report["starts"] = starts
    print(report, flush=True)
    save()

    # ------------------------------------------------------------------ single targets
    n_single = min(args.n_single, len(targets)) if "single" in parts else 0
    rows = []
    if n_single:
        t0 = time.perf_counter()
        jax.block_until_ready(inverse.inverse_statics(scene, targets[0], workspace=workspace))
        report["single_first_call_s (compile + solve)"] = time.perf_counter() - t0
    start = time.perf_counter()
    for i in range(n_single):
        if time.perf_counter() - start > args.budget:
            break
        t = time.perf_counter()
        res = inverse.inverse_statics(scene, targets[i], workspace=workspace)
        jax.block_until_ready(res)
        dt = time.perf_counter() - t
        rows.append(
            {
                "target": targets[i].tolist(),
                "controls_true": u_true[i].tolist(),
                "controls": np.asarray(res.controls).tolist(),
                "error_m": float(res.error),
                "reached": bool(res.reached),
                "iterations": int(res.iterations),
                "starts": int(res.starts),
                "seconds": dt,
            }
        )
        if len(rows) % 10 == 0 or len(rows) == n_single:
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
        res = inverse.inverse_statics(scene, target, workspace=workspace)
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
        track = inverse.track(scene, path, rtol=args.track_rtol, atol=1e-8, workspace=workspace)
        jumps = np.abs(np.diff(np.asarray(track.waypoints.controls), axis=0)).max(axis=1)
        report["track"] = {
            "waypoints": args.waypoints,
            "path": f"circle of radius 40 mm at z = -0.35 m (first waypoint from {starts})",
            "rtol, atol": [args.track_rtol, 1e-8],
            "reached": int(np.sum(np.asarray(track.waypoints.reached))),
            "max_error_m": float(np.max(np.asarray(track.waypoints.error))),
            "seconds (compiled solver)": track.seconds,
            "waypoints_per_second": track.waypoints_per_second,
            "max_command_jump_m": track.max_command_jump,
            "median_command_jump_m": float(np.median(jumps)),
            "iterations": _stats(np.asarray(track.waypoints.iterations)),
        }
        save()
        summary = {k: v for k, v in report["track"].items() if k != "iterations"}
        print("track:", summary, flush=True)

    # ------------------------------------------------------------------ batched
    n_batch = min(args.batch, len(targets)) if "batch" in parts else 0
    if n_batch:
        chunk = min(args.chunk, n_batch)
        kw = dict(workspace=workspace, chunk_size=chunk)
        t = time.perf_counter()  # compile on one chunk (and its polish)
        jax.block_until_ready(inverse.inverse_statics_batch(scene, targets[:chunk], **kw))
        first_s = time.perf_counter() - t
        t = time.perf_counter()
        out = inverse.inverse_statics_batch(scene, targets[:n_batch], **kw)
        jax.block_until_ready(out)
        warm = time.perf_counter() - t
        reached = np.asarray(out.reached)
        report["batched"] = {
            "n": n_batch,
            "chunk": chunk,
            "first_chunk_s (compile + solve)": first_s,
            "warm_s": warm,
            "seconds_per_target": warm / n_batch,
            "fraction_reached": float(np.mean(reached)),
            "not_reached": [
                {"target": targets[i].tolist(), "error_m": float(np.asarray(out.error)[i])}
                for i in np.flatnonzero(~reached)
            ],
            "error_m": _stats(np.asarray(out.error)),
            "iterations": _stats(np.asarray(out.iterations)),
            "starts": _stats(np.asarray(out.starts)),
        }
        save()
        print("batched:", {k: v for k, v in report["batched"].items() if k != "not_reached"})


if __name__ == "__main__":
    main()
