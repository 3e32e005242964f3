"""The paper's identification study (Stella et al., PAC), reproduced on synthetic ground truth.

The "real robot" is the paper's robot (``pj.presets.stella2023``) simulated at high fidelity:
cubic curvature per section (``PolynomialCurvature(order=3)``), bending stiffness growing with
contraction, 1 mm marker noise, 5 % dropped markers and an unknown mocap transform. PCC and PAC
(the preset's structure with start values off by 2x / 0.5x) are fitted on training frames; tip
position error (mm) and tip orientation error ``||R_pred - R_meas||_F`` are reported on held-out
frames, per load case, as the paper's bar charts do.

Cases:

- single section, perpendicular to gravity (``horizontal`` mount) and parallel to it
  (``hanging``), with 0 / 500 / 1000 g at the tip;
- three sections, hanging, with 0 / 200 / 400 g at the tip;
- three sections, hanging, with a 3.41 N follower force along the body at the tip (local +z:
  it keeps pulling along the tip's tangent as the robot bends; the paper's payload hung on a
  line run along the body).

Fitted: bending stiffness per section, axial stiffness, stiffening-with-contraction rate,
tendon gain, and the mocap transform. Usage::

    python experiments/paper_study/paper_study.py [--frames N] [--out DIR]

``--frames`` is per load case (train + held-out, a quarter held out). Results go to
``paper_study.json``, ``paper_study.md`` and ``paper_study.png``; compile and run times are
reported apart.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import jax
import numpy as np

import pacjax as pj

HERE = os.path.dirname(os.path.abspath(__file__))
MODELS = {"PCC": pj.PCC, "PAC": pj.PAC}
PARAMS = ("bending_stiffness", "axial_stiffness", "stiffening", "tendon_gain", "mocap_transform")
TIP_FORCE = 3.41  # N


def cases():
    """(name, scene kwargs, per-frame payloads (kg), follower force (N) or None)."""
    return [
        ("1 section, perpendicular", dict(n_sections=1, mount="horizontal"), (0.0, 0.5, 1.0), None),
        ("1 section, parallel", dict(n_sections=1, mount="hanging"), (0.0, 0.5, 1.0), None),
        ("3 sections, payload", dict(n_sections=3, mount="hanging"), (0.0, 0.2, 0.4), None),
        ("3 sections, follower 3.41 N", dict(n_sections=3, mount="hanging"), (0.0,), TIP_FORCE),
    ]


def commands(n_tendons, n, rng):
    """Random pull-ins: each tendon off or up to 25 mm (at most two per section pulled)."""
    u = rng.uniform(0.0, 0.025, (n, n_tendons))
    for k in range(0, n_tendons, 3):
        off = rng.integers(0, 3, n)
        u[np.arange(n), k + off] = 0.0
    return u


def start_scene(model, kwargs):
    """The preset with the model to fit, its estimates off by 2x (EI) and 0.5x (axial)."""
    scene = pj.presets.stella2023(model(), **kwargs)
    segs = [
        pj.Segment(
            s.length,
            2.0 * s.bending_stiffness,
            0.5 * s.axial_stiffness,
            s.torsion_stiffness,
            s.linear_density,
            s.radius,
            stiffening=pj.ExponentialStiffening(0.0),
        )
        for s in scene.robot.segments
    ]
    robot = pj.Robot(segs, scene.robot.base_rotation, scene.robot.base_position)
    return pj.Scene(robot, scene.model, scene.tendons, scene.loads, scene.markers)


def tip_frobenius(scene, report, truth_rot):
    """``||R_pred - R_meas||_F`` of the tip on held-out frames (mocap frame)."""
    out = []
    for q, r_meas in zip(report.validation.q, truth_rot, strict=True):
        _, r = pj.tip_pose(scene, q)
        out.append(np.linalg.norm(report.rotation @ np.asarray(r) - r_meas))
    return np.asarray(out)


def run(n_frames: int, seed: int = 0, save=None, only=None, previous=()):
    """Every case, both models; ``save(results)`` after every fit (a cut run keeps its rows).

    ``only``: run the cases whose name contains it, and keep the ``previous`` rows (by case
    name) of the others. The random draws of every case are still made in order, so a case
    sees the same frames as in a full run.
    """
    rng = np.random.default_rng(seed)
    kept = {row["case"]: row for row in previous}
    results = []
    for name, kwargs, payloads, force in cases():
        truth_scene = pj.presets.stella2023(pj.PAC(), **kwargs)
        n_tendons = truth_scene.n_tendons
        u = commands(n_tendons, n_frames, rng)
        mass = np.asarray(payloads)[rng.integers(0, len(payloads), n_frames)]
        if only is not None and only not in name:
            if name in kept:
                results.append(kept[name])
            continue
        extra = {}
        if force is not None:
            extra = dict(force=np.tile([0.0, 0.0, force], (n_frames, 1)), force_follower=True)
        t0 = time.perf_counter()
        data, truth = pj.synthetic_mocap(
            truth_scene,
            u,
            payload_mass=mass,
            noise=1e-3,
            dropout=0.05,
            orientations=True,
            orientation_noise=0.0,
            seed=seed,
            **extra,
        )
        t_data = time.perf_counter() - t0
        train, test = data.split(0.25, seed)
        # orientations are for evaluation only (the paper fits marker positions)
        strip = lambda d: pj.MocapDataset.from_arrays(  # noqa: E731
            d.controls,
            d.markers,
            d.sites,
            d.payload_mass,
            force=d.force,
            force_follower=d.force_follower,
        )
        tip_rot_test = test.orientations[:, -1]
        row = {
            "case": name,
            "frames": data.n_frames,
            "train": train.n_frames,
            "test": test.n_frames,
            "data_s": t_data,
            "models": {},
        }
        for model_name, model in MODELS.items():
            scene = start_scene(model, kwargs)
            t0 = time.perf_counter()
            fitted, report = pj.identify(
                scene,
                strip(train),
                PARAMS,
                per_segment=("bending_stiffness",),
                validation=strip(test),
                progress=False,
                max_iterations=30,
            )
            wall = time.perf_counter() - t0
            frob = tip_frobenius(fitted, report, tip_rot_test)
            v = report.validation
            row["models"][model_name] = {
                "tip_error_mm_mean": float(np.nanmean(v.tip_error_mm)),
                "tip_error_mm_std": float(np.nanstd(v.tip_error_mm)),
                "tip_frobenius_mean": float(np.mean(frob)),
                "tip_frobenius_std": float(np.std(frob)),
                "heldout_rmse_mm": v.rmse_mm,
                "train_rmse_mm": report.train.rmse_mm,
                "iterations": report.iterations,
                "fit_s": wall,
                "first_evaluation_s": report.first_evaluation_s,
                "parameters": {k: p["value"] for k, p in report.parameters.items()},
                "message": report.message,
            }
            print(
                f"{name:<30} {model_name}: tip {np.nanmean(v.tip_error_mm):.2f} mm, "
                f"Frobenius {np.mean(frob):.4f}, fit {wall:.0f} s",
                flush=True,
            )
            if save is not None:
                save(results + [row])
        results.append(row)
    return results


def write(results, out, n_frames, total_s, only=None):
    with open(os.path.join(out, "paper_study.json"), "w") as f:
        json.dump(
            {"frames_per_case": n_frames, "total_s": total_s, "only": only, "results": results},
            f,
            indent=2,
        )
    scope = "" if only is None else f" for the cases matching {only!r} (other rows: earlier run)"
    lines = [
        "# Paper study on synthetic truth",
        "",
        f"{n_frames} frames per case (a quarter held out), 1 mm marker noise, 5 % dropouts, "
        "unknown mocap transform; truth: cubic curvature + stiffening. Held-out tip errors, "
        f"mean +- std. Total {total_s:.0f} s{scope} ({jax.devices()[0].platform}).",
        "",
        "| case | model | tip error (mm) | tip Frobenius | held-out RMSE (mm) | train RMSE (mm) "
        "| iterations | fit (s) | first evaluation incl. compile (s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in results:
        for m, r in row["models"].items():
            lines.append(
                f"| {row['case']} | {m} | "
                f"{r['tip_error_mm_mean']:.2f} +- {r['tip_error_mm_std']:.2f} "
                f"| {r['tip_frobenius_mean']:.4f} +- {r['tip_frobenius_std']:.4f} | "
                f"{r['heldout_rmse_mm']:.2f} | {r['train_rmse_mm']:.2f} | {r['iterations']} | "
                f"{r['fit_s']:.0f} | {r['first_evaluation_s']:.0f} |"
            )
    with open(os.path.join(out, "paper_study.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 3.8))
    axes = fig.subplots(1, 2)
    x = np.arange(len(results))
    for k, (m, col) in enumerate((("PCC", "#1f77b4"), ("PAC", "#d62728"))):
        for ax, key, label in (
            (axes[0], "tip_error_mm", "tip position error (mm)"),
            (axes[1], "tip_frobenius", "tip orientation error (Frobenius)"),
        ):
            nan = {f"{key}_mean": np.nan, f"{key}_std": np.nan}
            mean = [r["models"].get(m, nan)[f"{key}_mean"] for r in results]
            std = [r["models"].get(m, nan)[f"{key}_std"] for r in results]
            ax.bar(x + (k - 0.5) * 0.38, mean, 0.38, yerr=std, color=col, label=m, capsize=3)
            ax.set_ylabel(label)
    for ax in axes:
        ax.set_xticks(x, [r["case"] for r in results], rotation=20, ha="right", fontsize=8)
        ax.grid(True, axis="y", alpha=0.3)
        ax.legend()
    fig.suptitle("Held-out errors after fitting PCC and PAC to synthetic mocap data")
    fig.tight_layout()
    FigureCanvasAgg(fig)
    fig.savefig(os.path.join(out, "paper_study.png"), dpi=110)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--out", default=HERE)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--only",
        help="Run only the cases whose name contains this text; the other cases' rows are "
        "kept from the existing paper_study.json in --out when it has the same --frames.",
    )
    args = parser.parse_args()
    previous = []
    existing = os.path.join(args.out, "paper_study.json")
    if args.only is not None and os.path.exists(existing):
        with open(existing) as f:
            record = json.load(f)
        if record["frames_per_case"] == args.frames:
            previous = record["results"]
    cache = os.environ.get("PACJAX_CACHE_DIR", os.path.expanduser("~/.cache/pacjax-jax"))
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    t0 = time.perf_counter()

    def save(results):
        write(results, args.out, args.frames, time.perf_counter() - t0, args.only)

    run(args.frames, args.seed, save, args.only, previous)


if __name__ == "__main__":
    main()
