#!/usr/bin/env python
"""float32 against float64 on the GPU benchmark's 10,000 commands, and what the worst rows are.

The paper's robot with PAC and 200 g (uniform 0-20 mm pull-ins, seed 0, as ``pacjax bench``),
solved in float64 (tolerance 1e-10) and float32 (1e-4). For the rows with the largest tip
difference, the float32 answer is re-solved in float64: landing on float64's equilibrium means a
flat valley that the float32 tolerance does not resolve; landing elsewhere, a second equilibrium.

    python benchmarks/float32_worst_rows.py [--n 10000] [--worst 3]
"""

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

import pacjax as pj
from pacjax.cli import bench


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=10000)
    parser.add_argument("--worst", type=int, default=3)
    args = parser.parse_args()
    scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
    commands = bench.random_commands(args.n, seed=0)
    tip = jax.jit(jax.vmap(lambda q: pj.tip_pose(scene, q)[0]))
    eqs, tips = {}, {}
    for dtype, tol in ((jnp.float64, 1e-10), (jnp.float32, 1e-4)):
        name = jnp.dtype(dtype).name
        sc = scene if dtype is jnp.float64 else pj.astype(scene, dtype)
        t0 = time.perf_counter()
        eqs[name] = pj.solve_batch(sc, jnp.asarray(commands, dtype), tol=tol)
        tips[name] = np.asarray(tip(jnp.asarray(eqs[name].q, jnp.float64)))
        print(
            f"{name}: {time.perf_counter() - t0:.0f} s, converged "
            f"{np.mean(eqs[name].converged):.4f}, stable {np.mean(eqs[name].stable):.4f}",
            flush=True,
        )
    diff = np.linalg.norm(tips["float64"] - tips["float32"], axis=1)
    print(
        f"tip difference: median {np.median(diff):.3e} m, rows > 0.05 mm: "
        f"{int(np.sum(diff > 5e-5))}, > 0.01 mm: {int(np.sum(diff > 1e-5))}"
    )
    ref = eqs["float64"]
    for i in np.argsort(diff)[::-1][: args.worst]:
        start = jnp.asarray(eqs["float32"].q[i], jnp.float64)
        again = pj.solve_equilibrium(scene, jnp.asarray(commands[i]), q0=start)
        t_again = np.asarray(pj.tip_pose(scene, again.q)[0])
        print(
            f"row {i}: float32 off by {diff[i]:.3e} m; re-solved in float64 from it: "
            f"converged {bool(again.converged)}, stable {bool(again.stable)}, "
            f"{np.linalg.norm(t_again - tips['float64'][i]):.1e} m from float64's tip, "
            f"energy {float(again.energy):.9f} vs {float(ref.energy[i]):.9f} J, "
            f"smallest scaled eigenvalue {float(ref.min_hessian_eigenvalue[i]):.2e}"
        )


if __name__ == "__main__":
    main()
