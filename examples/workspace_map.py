"""A workspace map: the tip positions the paper's robot reaches over random tendon pull-ins,
with a 200 g payload, coloured by the total pull-in.

    python examples/workspace_map.py            # 4,000 commands, writes workspace_map.png
    python examples/workspace_map.py --quick    # 64 commands (CI's smoke test)
"""

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import pacjax as pj


def main(quick: bool) -> None:
    scene = pj.presets.stella2023(pj.PAC(), tip_mass=0.2)
    # Commands drawn uniformly within the tendons' range (0 to half the length each spans);
    # only converged, stable equilibria are kept.
    workspace = pj.sample_workspace(scene, 64 if quick else 4000, seed=0)
    ok = np.asarray(workspace.converged)
    tips = 1e3 * np.asarray(workspace.tip)[ok]
    pull = 1e3 * np.asarray(workspace.controls)[ok].sum(axis=1)
    print(f"{ok.sum()} of {ok.size} commands reached a stable equilibrium")
    print(
        f"tip z from {tips[:, 2].min():.0f} to {tips[:, 2].max():.0f} mm, "
        f"radius up to {np.hypot(tips[:, 0], tips[:, 1]).max():.0f} mm"
    )

    fig, (top, side) = plt.subplots(1, 2, figsize=(9, 4.2), layout="constrained")
    for ax, (i, j), name in ((top, (0, 1), "from above"), (side, (0, 2), "from the side")):
        dots = ax.scatter(tips[:, i], tips[:, j], c=pull, s=4, cmap="viridis")
        ax.set(xlabel="xyz"[i] + " (mm)", ylabel="xyz"[j] + " (mm)", aspect="equal", title=name)
    fig.colorbar(dots, ax=side, label="total pull-in (mm)")
    fig.savefig("workspace_map.png", dpi=150)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a small setting (CI's smoke test)")
    main(parser.parse_args().quick)
