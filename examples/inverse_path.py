"""Inverse statics along a path: the tendon pull-ins that take the tip of the paper's robot,
carrying 200 g, around a horizontal circle.

    python examples/inverse_path.py            # 48 waypoints, writes inverse_path.png
    python examples/inverse_path.py --quick    # 4 waypoints (CI's smoke test)
"""

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import pacjax as pj


def main(quick: bool) -> None:
    scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
    n = 4 if quick else 48
    angle = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    # A circle of 60 mm radius, 300 mm below the base (the robot hangs 0.33 m long).
    waypoints = np.stack([0.06 * np.cos(angle), 0.06 * np.sin(angle), np.full(n, -0.30)], 1)
    tracked = pj.track(scene, waypoints)
    result = tracked.waypoints
    reached = np.asarray(result.reached)
    error_mm = 1e3 * np.asarray(result.error)
    print(f"{reached.sum()} of {n} waypoints reached; largest tip error {error_mm.max():.3f} mm")
    print(f"largest change of a pull-in between waypoints: {1e3 * tracked.max_command_jump:.1f} mm")

    controls = 1e3 * np.asarray(result.controls)
    fig, ax = plt.subplots(figsize=(6.5, 3.8), layout="constrained")
    for k in range(controls.shape[1]):
        section, tendon = divmod(k, 3)
        ax.plot(
            np.degrees(angle),
            controls[:, k],
            marker=".",
            color=f"C{tendon}",
            linestyle=("-", "--", ":")[section],
            label=f"section {section + 1}, tendon {tendon + 1}",
        )
    ax.set(
        xlabel="angle around the circle (deg)",
        ylabel="pull-in (mm)",
        title="Commands along a circle of the tip",
    )
    ax.legend(fontsize="x-small", ncols=3)
    fig.savefig("inverse_path.png", dpi=150)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a small setting (CI's smoke test)")
    main(parser.parse_args().quick)
