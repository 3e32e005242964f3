"""Your own robot from scratch: a tapered silicone arm with two tendons in continuous channels,
bent by a sweep of tensions, with its backbones drawn.

    python examples/own_robot.py            # 9 tensions, writes own_robot.png
    python examples/own_robot.py --quick    # 3 tensions (CI's smoke test)
"""

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import pacjax as pj


def build_scene() -> pj.Scene:
    # One 0.2 m segment of silicone (E = 1.2 MPa), 12 mm radius at the base tapering to 8 mm.
    body = pj.Segment.from_material(
        0.2, young_modulus=1.2e6, radius=0.012, radius_tip=0.008, density=1070.0
    )
    # Two channels on opposite sides, 10 mm off the centreline at the base and 6 mm at the tip,
    # driven in tension (N) by torque-controlled spools.
    tendons = [
        pj.Tendon(0, angle, 0.010, offset_end=0.006, routing="channel", mode="tension")
        for angle in (np.pi / 2, -np.pi / 2)
    ]
    return pj.Scene(
        pj.Robot([body], base_rotation=pj.presets.MOUNTS["hanging"]),  # axis down
        pj.PAC(),
        tendons=tendons,
        loads=[pj.Gravity()],
        markers=[(0, 0.5), (0, 1.0)],
    )


def main(quick: bool) -> None:
    scene = build_scene()
    tensions = np.linspace(0.0, 6.0, 3 if quick else 9)
    controls = np.stack([tensions, np.zeros_like(tensions)], axis=1)  # pull the +y tendon only
    batch = pj.solve_batch(scene, controls)
    print(f"{int(np.sum(batch.successful))} of {len(tensions)} equilibria converged")

    fig, ax = plt.subplots(figsize=(4.5, 5))
    for tension, q in zip(tensions, batch.q, strict=True):
        points = np.asarray(pj.backbone(scene, q)[0])  # positions (50, 3)
        ax.plot(1e3 * points[:, 1], 1e3 * points[:, 2], label=f"{tension:.2f} N")
        tip, _ = pj.tip_pose(scene, q)
        print(f"tension {tension:4.2f} N: tip at {np.round(1e3 * np.asarray(tip), 1)} mm")
    ax.set(xlabel="y (mm)", ylabel="z (mm)", aspect="equal", title="Tip bending under tension")
    ax.legend(title="tendon +y", fontsize="small")
    fig.savefig("own_robot.png", dpi=150, bbox_inches="tight")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a small setting (CI's smoke test)")
    main(parser.parse_args().quick)
