"""Fit a robot's bending and axial stiffness to motion capture; check it on held-out frames.

    python examples/fit_mocap.py SCENE.toml FRAMES.csv   # your scene file and mocap CSV
    python examples/fit_mocap.py                         # a recording of a made-up robot
    python examples/fit_mocap.py --quick                 # fewer frames (CI's smoke test)

Without files, the example records frames of ``experiments/scenes/tendon_single.toml`` whose
true bending stiffness is 30 % above the scene's and its axial stiffness 20 % below, with 1 mm of
marker noise, writes them as a mocap CSV, and fits the scene to that file. The CSV format is
in ``docs/identification.md``.
"""

import argparse
from pathlib import Path

import equinox as eqx
import numpy as np

import pacjax as pj
from pacjax.io.mocapfile import load_mocap, save_mocap
from pacjax.io.scenefile import load_scene

SCENE = Path(__file__).resolve().parents[1] / "experiments" / "scenes" / "tendon_single.toml"


def record_made_up_frames(scene: pj.Scene, path: Path, n_frames: int) -> None:
    """Frames of the scene with other stiffness values, as a mocap CSV at ``path``."""
    segment = scene.robot.segments[0]
    truth = eqx.tree_at(
        lambda s: (s.robot.segments[0].bending_stiffness, s.robot.segments[0].axial_stiffness),
        scene,
        (1.3 * segment.bending_stiffness, 0.8 * segment.axial_stiffness),
    )
    tensions = np.random.default_rng(1).uniform(0.0, 4.0, (n_frames, len(scene.tendons)))
    # exact=True: the frames come from the same model, so the fit can recover the truth up to
    # the noise (without it they come from a finer model, as real data would).
    dataset, _ = pj.synthetic_mocap(truth, tensions, noise=1e-3, transform=None, exact=True)
    save_mocap(path, dataset)
    true = truth.robot.segments[0]
    print(
        f"made up {n_frames} frames of a robot with EI = {true.bending_stiffness:.4g} N m^2, "
        f"EA/L = {true.axial_stiffness:.4g} N/m: {path}"
    )


def main(scene_path: Path, csv_path: Path | None, quick: bool) -> None:
    scene, _, _ = load_scene(scene_path)
    if csv_path is None:
        csv_path = Path("made_up_frames.csv")
        record_made_up_frames(scene, csv_path, 12 if quick else 40)
    data = load_mocap(csv_path)
    fitted, report = pj.identify(
        scene, data, params=("bending_stiffness", "axial_stiffness"), holdout=0.25, seed=0
    )
    print(report.to_markdown())
    before = scene.robot.segments[0]
    after = fitted.robot.segments[0]
    print(f"EI:   {before.bending_stiffness:.4g} -> {after.bending_stiffness:.4g} N m^2")
    print(f"EA/L: {before.axial_stiffness:.4g} -> {after.axial_stiffness:.4g} N/m")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", nargs="?", type=Path, default=SCENE, help="a TOML scene file")
    parser.add_argument("frames", nargs="?", type=Path, help="a mocap CSV (default: made up)")
    parser.add_argument("--quick", action="store_true", help="a small setting (CI's smoke test)")
    args = parser.parse_args()
    main(args.scene, args.frames, args.quick)
