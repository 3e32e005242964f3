"""The deep profile of the scene-space campaign (issue 28): many structures from the space a user
can write (``tests/scene_space.py``: 1-24 segments, every strain model and per-segment mixes,
0-20 point masses, forces and moments at arbitrary sites, tendons with 2-40 rings or channels,
anchors anywhere, length and tension mode, gravity and base in any direction, float32 and
float64), many value draws on each, every property checked on each draw.

Each structure costs its compilations (tens of seconds on 2 cores); its draws reuse them. Every
draw is recorded (structure, result code, any broken property or exception with its
traceback's last line) in ``benchmarks/results/campaign.json``, rewritten after every structure
so that an interrupted run keeps what it did; ``--resume`` continues one.

    python benchmarks/campaign.py --structures 200 --draws 50 [--seed 0] [--resume]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
import traceback
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from scene_space import PropertyFailure, build, check, draw_structure, values  # noqa: E402

OUT = ROOT / "benchmarks" / "results" / "campaign.json"
#: Beyond the single and batch solves, on every draw (each one compilation per structure).
OPERATIONS = ("gradient", "find_equilibria", "simulate")


def run_structure(structure, draws: int, seed: int) -> list[dict]:
    """``draws`` value draws on one structure; one record per draw."""
    records = []

    @settings(
        max_examples=draws,
        deadline=None,
        database=None,
        derandomize=False,
        suppress_health_check=list(HealthCheck),
    )
    @given(data=st.data())
    def one(data):
        record = {"structure": structure.describe()}
        t0 = time.perf_counter()
        try:
            scene, controls = build(structure, data.draw(values(structure)))
        except (ValueError, TypeError) as err:  # a documented validation error
            record.update(outcome="rejected", error=str(err))
        else:
            try:
                found = check(scene, controls, structure.dtype, OPERATIONS)
                record.update(outcome="ok", **found)
            except PropertyFailure as err:
                record.update(outcome="property", error=str(err))
            except Exception as err:  # noqa: BLE001 -- a crash is what the campaign looks for
                last = traceback.format_exc().strip().splitlines()[-1]
                record.update(outcome="crash", error=f"{type(err).__name__}: {last}")
        record["seconds"] = time.perf_counter() - t0
        records.append(record)

    np.random.seed(seed)  # hypothesis seeds from its own generator; keep numpy's fixed too
    one()
    return records


def main(n_structures: int, draws: int, seed: int, resume: bool) -> dict:
    warnings.simplefilter("ignore")
    rng = np.random.default_rng(seed)
    done = json.loads(OUT.read_text()) if resume and OUT.exists() else None
    records = done["records"] if done else []
    start = done["structures_done"] if done else 0
    structures = [draw_structure(rng) for _ in range(n_structures)]
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT
    ).stdout.strip()
    t0 = time.perf_counter()
    for k in range(start, n_structures):
        records += run_structure(structures[k], draws, seed + k)
        tally = Counter(r["outcome"] for r in records)
        result = {
            "commit": commit,
            "date": time.strftime("%Y-%m-%d"),
            "seed": seed,
            "structures_done": k + 1,
            "draws": len(records),
            "tally": dict(tally),
            "results": dict(Counter(r.get("single", "-") for r in records)),
            "wall_s": (done or {}).get("wall_s", 0.0) + time.perf_counter() - t0,
            "records": records,
        }
        OUT.write_text(json.dumps(result, indent=1) + "\n")
        print(f"{k + 1}/{n_structures} {structures[k].describe()}: {dict(tally)}", flush=True)
    return result


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--structures", type=int, default=200)
    parser.add_argument("--draws", type=int, default=50)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--resume", action="store_true")
    args = parser.parse_args()
    main(args.structures, args.draws, args.seed, args.resume)
