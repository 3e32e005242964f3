"""Steps per pool round on the accelerator: problem (a) and (b) of vs_soromox, pacjax PAC and
Poly1, rounds of R steps alternated in one process (per_round is a traced argument: one
program). Prints medians of warm calls."""
import json, os, sys, time
import numpy as np
sys.path.insert(0, "benchmarks")
import vs_soromox as vs
from pacjax._statics import pool

n_rows = [int(x) for x in os.environ.get("ROWS", "10000").split(",")]
rounds = [int(x) for x in os.environ.get("ROUNDS", "4,8,64").split(",")]
repeats = int(os.environ.get("REPEATS", "3"))
out = {}
for key in os.environ.get("PROBLEMS", "a,b").split(","):
    prob = vs.PROBLEMS[key]
    for model in ("PAC", "Poly1"):
        scene = vs.pacjax_scene(prob, vs.MODELS[model]())
        for n in n_rows:
            rows = prob.rows(n)
            call = lambda: vs.pacjax_batch(prob, scene, rows)
            first, eq = vs.timed(call)
            times = {r: [] for r in rounds}
            for rep in range(repeats):
                for r in rounds if rep % 2 == 0 else rounds[::-1]:
                    pool._STEPS_PER_ROUND_DEFAULT = r
                    pool.STEPS_PER_ROUND["cpu"] = r
                    times[r].append(vs.timed(call)[0])
            med = {r: float(np.median(t)) for r, t in times.items()}
            steps = np.asarray(eq.steps)
            line = (f"({key}) {model} n={n} first {first:.1f} s, steps {steps.mean():.2f}/{steps.max()}: "
                    + ", ".join(f"R={r} {med[r]*1e3:.1f} ms ({n/med[r]:.0f} eq/s)" for r in rounds))
            print(line, flush=True)
            out[f"{key}_{model}_{n}"] = {"first_s": first, "warm_s": times, "steps_mean": float(steps.mean()), "steps_max": int(steps.max())}
            with open(os.path.join(os.environ.get("OUT", "/tmp"), "gpu_rounds.json"), "w") as f:
                json.dump(out, f, indent=1)
