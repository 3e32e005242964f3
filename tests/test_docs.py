"""The README's and the documentation's Python examples run as written (the ones that read a
user's file are run on a file written first), and the README stays short."""

import re
from pathlib import Path

import numpy as np
import pytest

import pacjax as pj

ROOT = Path(__file__).resolve().parents[1]


def _blocks(path: Path) -> list[str]:
    text = path.read_text(encoding="utf-8")
    return [
        re.sub(r"(?m)^    ", "", b) if b.startswith("    ") else b
        for b in re.findall(r"```python\n(.*?)```", text, re.S)
    ]


def test_the_readme_fits_on_two_screens():
    assert len((ROOT / "README.md").read_text(encoding="utf-8").splitlines()) <= 150


@pytest.mark.slow  # solves and a fit: compilations
def test_the_readme_examples_run(tmp_path, monkeypatch):
    from pacjax.io.mocapfile import save_mocap

    monkeypatch.chdir(tmp_path)
    blocks = _blocks(ROOT / "README.md")
    namespace: dict = {}
    exec(blocks[0], namespace)  # noqa: S102 -- the first script
    exec(blocks[1], namespace)  # noqa: S102 -- your own robot
    scene = namespace["scene"]
    truth = pj.synthetic_mocap(
        scene, np.linspace(0.5, 3.0, 6)[:, None], exact=True, noise=1e-3, transform=None
    )[0]
    save_mocap(tmp_path / "frames.csv", truth)
    exec(blocks[2], namespace)  # noqa: S102 -- the fit, on frames.csv written above
    assert namespace["report"].successful
