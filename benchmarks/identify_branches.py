"""The cost and the effect of identification's branch checks on the real tentacle.

Fits bending stiffness and linear density of ``pj.presets.tentacle((PAC(), PCC()))`` from the
README's guess to the eight takes of ``shared/data/soromox_tentacle``, alternating
``branch_starts=0`` and the default 8 after one warm-up fit, and writes the wall times, batch
evaluations, RMSE, the branch summary and the medians to
``benchmarks/results/identify_branches.json``.

    python benchmarks/identify_branches.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import pacjax as pj

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments" / "real_tentacle"))
import study  # noqa: E402

PARAMS = ("bending_stiffness", "linear_density")


def main(repeats: int) -> dict:
    _, tensions, markers = study.load_takes()
    scene = pj.presets.tentacle(study.MODELS["pac-pcc"](), **study.GUESS)
    data = pj.MocapDataset.from_arrays(tensions, markers, scene.markers)
    t0 = time.perf_counter()
    pj.identify(scene, data, PARAMS, progress=False)
    runs = {"first_fit_s": time.perf_counter() - t0, 0: [], 8: []}
    for _ in range(repeats):
        for starts in (0, 8):
            t0 = time.perf_counter()
            _, report = pj.identify(scene, data, PARAMS, branch_starts=starts, progress=False)
            runs[starts].append(
                {
                    "wall_s": time.perf_counter() - t0,
                    "evaluations": report.evaluations,
                    "rmse_mm": report.train.rmse_mm,
                    "frame_rmse_mm": report.train.frame_rmse_mm.tolist(),
                    "message": report.message,
                    "branches": report.branches.summary(),
                }
            )
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT
    ).stdout.strip()
    result = {
        "commit": commit,
        "date": time.strftime("%Y-%m-%d"),
        "first_fit_s": runs["first_fit_s"],
        "median_wall_s": {str(k): float(np.median([r["wall_s"] for r in runs[k]])) for k in (0, 8)},
        "branch_starts_0": runs[0],
        "branch_starts_8": runs[8],
    }
    out = ROOT / "benchmarks" / "results" / "identify_branches.json"
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result["median_wall_s"]), f"-> {out}")
    return result


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    main(parser.parse_args().repeats)
