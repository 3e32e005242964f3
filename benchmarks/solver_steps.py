"""Solver steps per equilibrium on the robots of issue 25: the paper's robot (rings, length
mode), the tentacle (channels, tension mode, hanging) and a horizontal cantilever under gravity
and a tip force, each with PAC (polar) and ``PolynomialCurvature(1)`` (the same affine
curvature in strain coordinates). Counts are the solver's ``steps`` (the first linearisation
at the start included), so they do not depend on the machine.

Usage: python benchmarks/solver_steps.py [rows] [out.json] [--continuation-only]

``--continuation-only``: the baseline, every strain model starting the continuation from
``initial_dt`` (no Newton start, :meth:`pacjax.StrainModel.newton_from_start` False).
"""

import json
import subprocess
import sys
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import pacjax as pj

#: The cantilever: silicone (E, density), 10 mm radius, 0.3 m.
E, DENSITY, RADIUS, LENGTH = 5.05e5, 1500.0, 0.01, 0.3


def cantilever(model) -> pj.Scene:
    inertia, area = np.pi * RADIUS**4 / 4, np.pi * RADIUS**2
    segment = pj.Segment(
        LENGTH, E * inertia, E * area / LENGTH, linear_density=DENSITY * area, radius=RADIUS
    )
    robot = pj.Robot([segment], base_rotation=pj.presets.MOUNTS["horizontal"])
    return pj.Scene(robot, model, (), (pj.Gravity(), pj.PointForce(np.zeros(3), 0, 1.0)))


def cases(rows: int):
    rng = np.random.default_rng(1)
    tensions = jnp.asarray(rng.uniform(0.0, 8.0, (rows, 2)))
    pull_ins = jnp.asarray(rng.uniform(0.0, 0.04, (rows, 9)))
    forces = jnp.asarray(rng.uniform(-2.0, 2.0, (rows, 3)))

    def set_force(scene, force):
        return eqx.tree_at(lambda s: s.loads[1].force, scene, force)

    for model in (pj.PAC(), pj.PolynomialCurvature(1)):
        name = type(model).__name__ + ("(1)" if isinstance(model, pj.PolynomialCurvature) else "")
        yield f"paper robot, {name}", pj.presets.stella2023(model), pull_ins, {}
        yield f"tentacle, {name}", pj.presets.tentacle(model), tensions, {}
        yield (
            f"cantilever, {name}",
            cantilever(model),
            jnp.zeros((rows, 0)),
            {"params": forces, "update": set_force},
        )


def main(rows: int = 1000, out: str | None = None) -> dict:
    record = {
        "date": time.strftime("%Y-%m-%d"),
        "commit": subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True
        ).stdout.strip(),
        "jax": jax.__version__,
        "rows": rows,
        "newton_start": pj.PolynomialCurvature(1).newton_from_start(),
        "cases": {},
    }
    for name, scene, controls, extra in cases(rows):
        eq = pj.solve_batch(scene, controls, **extra)
        steps = np.asarray(eq.steps)
        result = {
            "converged": float(np.mean(eq.converged)),
            "stable": float(np.mean(eq.stable)),
            "mean_steps": float(steps.mean()),
            "max_steps": int(steps.max()),
        }
        record["cases"][name] = result
        print(
            f"{name:32s} converged {result['converged']:.3f}  stable {result['stable']:.3f}  "
            f"steps mean {result['mean_steps']:.2f} max {result['max_steps']}",
            flush=True,
        )
    if out:
        with open(out, "w") as f:
            json.dump(record, f, indent=1)
    return record


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if a != "--continuation-only"]
    if "--continuation-only" in sys.argv:
        pj.StrainModel.newton_from_start = lambda self: False
    main(int(args[0]) if args else 1000, args[1] if len(args) > 1 else None)
