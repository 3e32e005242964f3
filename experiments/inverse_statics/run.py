"""Inverse statics experiments on the paper's robot (PAC, hanging):

1. a load-aware trajectory: the same tip path tracked with 0, 200 and 400 g at the tip. The
   commands differ (the payload changes the answer); figure ``load_aware_path.png``, commands in
   ``load_aware_path.json``;
2. the workspace: tips of random commands within the default range (forward solves), with the
   path drawn in; figure ``workspace.png``, summary in ``workspace.json``.

    python experiments/inverse_statics/run.py [--waypoints 40] [--samples 300]
"""

import argparse
import json
import os
import time

import jax
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

import pacjax as pj

HERE = os.path.dirname(os.path.abspath(__file__))
PAYLOADS = (0.0, 0.2, 0.4)  # kg
COLORS = ("tab:blue", "tab:orange", "tab:red")


def enable_cache():
    cache = os.environ.get("PACJAX_CACHE_DIR", os.path.expanduser("~/.cache/pacjax-jax"))
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


def paper_scene(payload):
    """The paper's robot with ``payload`` kg at the tip. The payload is always a
    :class:`pacjax.PointMass` (0 kg included), so the three payloads share one compiled solver
    (the preset's ``tip_mass=0`` leaves the mass out, a different structure)."""
    return pj.presets.stella2023(pj.PAC(), loads=(pj.PointMass(payload, 2, 1.0),))


def path(n):
    """A closed tip path: a circle of 40 mm radius, 0.35 m below the base."""
    angle = np.linspace(0.0, 2.0 * np.pi, n)
    return np.stack([0.04 * np.cos(angle), 0.04 * np.sin(angle), np.full(n, -0.35)], -1)


def load_aware(n_waypoints, out):
    waypoints = path(n_waypoints)
    runs = {}
    for mass in PAYLOADS:
        scene = paper_scene(mass)
        # warm-started waypoints: a loose Levenberg-Marquardt tolerance is enough
        tracked = pj.track(scene, waypoints, rtol=1e-2, atol=1e-8)
        res = tracked.waypoints
        runs[mass] = (scene, tracked)
        print(
            f"{1e3 * mass:.0f} g: {int(np.sum(res.reached))}/{n_waypoints} reached, "
            f"max error {1e3 * float(np.max(res.error)):.3g} mm, "
            f"max command jump {1e3 * tracked.max_command_jump:.2f} mm, "
            f"{tracked.waypoints_per_second:.2f} waypoints/s",
            flush=True,
        )
    summary = {
        "path": "circle, radius 40 mm, z = -0.35 m (base at the origin, robot hanging along -z)",
        "waypoints": waypoints.tolist(),
        "runs": {
            f"{1e3 * m:.0f} g": {
                "reached": np.asarray(t.waypoints.reached).tolist(),
                "error_m": np.asarray(t.waypoints.error).tolist(),
                "controls_m": np.asarray(t.waypoints.controls).tolist(),
                "tensions_N": np.asarray(t.waypoints.tensions).tolist(),
                "max_command_jump_m": t.max_command_jump,
                "waypoints_per_second": t.waypoints_per_second,
                "seconds": t.seconds,
            }
            for m, (_, t) in runs.items()
        },
    }
    with open(os.path.join(out, "load_aware_path.json"), "w", encoding="utf-8") as f:
        json.dump(summary, f, indent=1)

    fig = Figure(figsize=(15, 8.5), layout="constrained")
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(2, 4)
    ax3 = fig.add_subplot(grid[:, :2], projection="3d")
    shown = np.linspace(0, n_waypoints - 1, 5).astype(int)[:-1]
    for (mass, (scene, tracked)), color in zip(runs.items(), COLORS, strict=True):
        for i in shown:
            pts, _ = pj.backbone(scene, tracked.waypoints.q[i], 40)
            pts = 1e3 * np.asarray(pts)
            ax3.plot(
                *pts.T,
                color=color,
                lw=2,
                alpha=0.8,
                label=f"{1e3 * mass:.0f} g" if i == shown[0] else None,
            )
    ax3.plot(*(1e3 * waypoints).T, "k--", lw=1.5, label="tip path")
    ax3.set_xlabel("x (mm)")
    ax3.set_ylabel("y (mm)")
    ax3.set_zlabel("z (mm)")
    ax3.set_box_aspect((1, 1, 2))
    ax3.legend(loc="upper left")
    ax3.set_title("reached backbones at 4 waypoints")
    waypoint = np.arange(n_waypoints)
    for k in range(3):  # one panel per section
        ax = fig.add_subplot(grid[k // 2, 2 + k % 2])
        for (_, tracked), color in zip(runs.values(), COLORS, strict=True):
            u = 1e3 * np.asarray(tracked.waypoints.controls)
            for j, style in zip(range(3), ("-", "--", ":"), strict=True):
                ax.plot(waypoint, u[:, 3 * k + j], style, color=color, lw=1.5)
        ax.set_title(f"section {k + 1}: pull-in of its 3 tendons (-, --, :)")
        ax.set_xlabel("waypoint")
        ax.set_ylabel("command (mm)")
        ax.grid(True, color="0.9")
    ax = fig.add_subplot(grid[1, 3])
    for (mass, (_, tracked)), color in zip(runs.items(), COLORS, strict=True):
        ax.semilogy(
            waypoint,
            1e3 * np.maximum(np.asarray(tracked.waypoints.error), 1e-9),
            color=color,
            label=f"{1e3 * mass:.0f} g",
        )
    ax.axhline(0.1, color="k", lw=1, ls="--", label="0.1 mm")
    ax.set_title("tip error")
    ax.set_xlabel("waypoint")
    ax.set_ylabel("error (mm)")
    ax.legend()
    fig.suptitle("Stella et al. 2023 robot (PAC): one tip path, three payloads, three command sets")
    fig.savefig(os.path.join(out, "load_aware_path.png"), dpi=100)
    return waypoints


def workspace(n_samples, waypoints, out):
    scene = paper_scene(0.0)
    t = time.perf_counter()
    ws = pj.sample_workspace(scene, n_samples, seed=1)
    seconds = time.perf_counter() - t
    tip = 1e3 * np.asarray(ws.tip)[np.asarray(ws.converged)]
    summary = {
        "samples": n_samples,
        "converged_stable": int(np.sum(np.asarray(ws.converged))),
        "seconds (forward batch, compile included)": seconds,
        "tip_min_mm": tip.min(0).tolist(),
        "tip_max_mm": tip.max(0).tolist(),
        "max_radius_mm": float(np.max(np.linalg.norm(tip[:, :2], axis=1))),
    }
    with open(os.path.join(out, "workspace.json"), "w", encoding="utf-8") as f:
        json.dump(summary, f, indent=1)
    print("workspace:", summary, flush=True)
    fig = Figure(figsize=(14, 4.8), layout="constrained")
    FigureCanvasAgg(fig)
    for k, (i, j) in enumerate(((0, 2), (1, 2), (0, 1))):
        ax = fig.add_subplot(1, 3, k + 1)
        sc = ax.scatter(tip[:, i], tip[:, j], c=tip[:, 2], s=6, cmap="viridis")
        ax.plot(1e3 * waypoints[:, i], 1e3 * waypoints[:, j], "r-", lw=1.5, label="tracked path")
        ax.set_xlabel("xyz"[i] + " (mm)")
        ax.set_ylabel("xyz"[j] + " (mm)")
        ax.set_aspect("equal")
        ax.grid(True, color="0.9")
        if k == 0:
            ax.legend()
    fig.colorbar(sc, label="tip z (mm)")
    fig.suptitle(
        f"Workspace of the Stella et al. 2023 robot (PAC, no payload): tips of {len(tip)} random "
        "commands within 0-67.7 mm"
    )
    fig.savefig(os.path.join(out, "workspace.png"), dpi=100)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--waypoints", type=int, default=40)
    parser.add_argument("--samples", type=int, default=300)
    parser.add_argument("--out", default=HERE)
    args = parser.parse_args()
    enable_cache()
    waypoints = load_aware(args.waypoints, args.out)
    workspace(args.samples, waypoints, args.out)


if __name__ == "__main__":
    main()
