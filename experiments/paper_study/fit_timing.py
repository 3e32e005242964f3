"""Time a fit on 200 frames of the paper's robot, from a start 3x off (issue 4 acceptance).

Synthetic data from the paper's robot itself (``exact=True``: every parameter recoverable) with
1 mm marker noise, 5 % dropouts, payloads 0 / 200 / 400 g and an unknown mocap transform. The
fit estimates bending stiffness, axial stiffness, linear density, ``kappa_P`` and the transform,
starting from 3x (or 1/3x) the true values. Reports the first evaluation (compilation included)
apart from the rest, and the recovered values. Usage::

    python experiments/paper_study/fit_timing.py [--frames 200] [--model PAC|PCC]
"""

import argparse
import json
import os
import time

import equinox as eqx
import jax
import numpy as np

import pacjax as pj

PARAMS = (
    "bending_stiffness",
    "axial_stiffness",
    "linear_density",
    "tendon_gain",
    "mocap_transform",
)


def scaled(scene, factors):
    """The scene with bending, axial stiffness, density and gains multiplied by ``factors``."""
    fe, fa, fd, fg = factors
    scene = eqx.tree_at(
        lambda s: (
            [x.bending_stiffness for x in s.robot.segments]
            + [x.axial_stiffness for x in s.robot.segments]
            + [x.linear_density for x in s.robot.segments]
            + [t.gain for t in s.tendons]
        ),
        scene,
        [fe * x.bending_stiffness for x in scene.robot.segments]
        + [fa * x.axial_stiffness for x in scene.robot.segments]
        + [fd * x.linear_density for x in scene.robot.segments]
        + [fg * t.gain for t in scene.tendons],
    )
    return scene


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--model", default="PAC", choices=("PAC", "PCC"))
    parser.add_argument("--out", default=os.path.dirname(os.path.abspath(__file__)))
    args = parser.parse_args()
    cache = os.environ.get("PACJAX_CACHE_DIR", os.path.expanduser("~/.cache/pacjax-jax"))
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    model = {"PAC": pj.PAC, "PCC": pj.PCC}[args.model]()
    truth = pj.presets.stella2023(model, stiffening=False)
    rng = np.random.default_rng(0)
    n = args.frames
    u = rng.uniform(0.0, 0.025, (n, truth.n_tendons))
    for k in range(0, truth.n_tendons, 3):
        u[np.arange(n), k + rng.integers(0, 3, n)] = 0.0
    mass = rng.choice([0.0, 0.2, 0.4], n)
    t0 = time.perf_counter()
    data, _ = pj.synthetic_mocap(truth, u, payload_mass=mass, exact=True, dropout=0.05, seed=1)
    t_data = time.perf_counter() - t0
    start = scaled(truth, (3.0, 1 / 3, 3.0, 1 / 3))
    t0 = time.perf_counter()
    fitted, report = pj.identify(start, data, PARAMS, holdout=0.2, progress=False)
    wall = time.perf_counter() - t0
    truth_values = {
        "bending_stiffness": float(truth.robot.segments[0].bending_stiffness),
        "axial_stiffness": float(truth.robot.segments[0].axial_stiffness),
        "linear_density": float(truth.robot.segments[0].linear_density),
        "tendon_gain": float(truth.tendons[0].gain),
    }
    rows = {}
    for name, true in truth_values.items():
        p = report.parameters[name]
        rows[name] = {
            "truth": true,
            "initial": p["initial"][0],
            "fitted": p["value"][0],
            "error_percent": 100 * (p["value"][0] / true - 1),
            "std_percent": 100 * p["relative_std"][0],
        }
    result = {
        "model": args.model,
        "frames": data.n_frames,
        "train_frames": len(report.train.q),
        "data_s": t_data,
        "fit_s": wall,
        "first_evaluation_s": report.first_evaluation_s,
        "evaluations": report.evaluations,
        "iterations": report.iterations,
        "message": report.message,
        "train_rmse_mm": report.train.rmse_mm,
        "heldout_rmse_mm": report.validation.rmse_mm,
        "parameters": rows,
        "cpu_count": os.cpu_count(),
    }
    print(json.dumps(result, indent=2))
    with open(os.path.join(args.out, f"fit_timing_{args.model}.json"), "w") as f:
        json.dump(result, f, indent=2)


if __name__ == "__main__":
    main()
