"""A dynamic step response: one upright segment whose tendon tension jumps from 0 to 3 N, with
the tip's motion until it settles, against the static equilibrium it settles to.

    python examples/step_response.py            # 1 s, writes step_response.png
    python examples/step_response.py --quick    # 0.05 s (CI's smoke test)
"""

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import pacjax as pj
from pacjax.io.scenefile import load_scene

SCENE = Path(__file__).resolve().parents[1] / "experiments" / "scenes" / "tendon_single.toml"


def main(quick: bool) -> None:
    scene, _, _ = load_scene(SCENE)  # three tendons in tension mode, EI 0.02 N m^2, 12 cm
    step = np.array([3.0, 0.0, 0.0])  # N, from rest and straight at t = 0
    duration = 0.05 if quick else 1.0
    times = np.linspace(0.0, duration, 201)
    trajectory = pj.simulate(scene, (0.0, duration), step, saveat=times)
    tips = 1e3 * np.asarray([pj.tip_pose(scene, q)[0] for q in trajectory.q])
    settled = pj.solve_equilibrium(scene, step)
    target = 1e3 * np.asarray(pj.tip_pose(scene, settled.q)[0])
    print(f"{int(trajectory.num_accepted_steps)} steps accepted of {int(trajectory.num_steps)}")
    print(
        f"tip at {duration} s: {np.round(tips[-1], 2)} mm; static equilibrium: "
        f"{np.round(target, 2)} mm ({np.linalg.norm(tips[-1] - target):.3f} mm apart)"
    )

    fig, ax = plt.subplots(figsize=(6, 3.5), layout="constrained")
    ax.plot(times, tips[:, 1], label="tip y, simulated")
    ax.axhline(target[1], color="k", linestyle="--", linewidth=1, label="tip y, static equilibrium")
    ax.set(xlabel="time (s)", ylabel="tip y (mm)", title="Step of 3 N on tendon 1")
    ax.legend()
    fig.savefig("step_response.png", dpi=150)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a small setting (CI's smoke test)")
    main(parser.parse_args().quick)
