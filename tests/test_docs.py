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


#: What a measurement history looks like in prose; such figures belong in benchmarks/RESULTS.md.
_HISTORY = [
    r"\beq/s\b",
    r"\d(\.\d+)? ?(s|ms|us|min)\b[^.]{0,40}\b(against|instead of)\s+\d",
    r"\bwas\b[^.]{0,40}\d[^.]{0,40}\bbefore\b",
    r"\b20\d\d-\d\d-\d\d\b",
    r"\bon \d+ (CPU )?cores\b",
    r"\d(\.\d+)?x (faster|slower)\b",
    r"\d(\.\d+)? ?-> ?\d",
]


def _comments_and_docstrings(path: Path):
    import ast
    import io
    import tokenize

    source = path.read_text(encoding="utf-8")
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            yield token.start[0], token.string
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Module | ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            doc = ast.get_docstring(node, clean=False)
            if doc:
                yield getattr(node, "lineno", 1), doc


def test_the_code_states_contracts_not_measurement_histories():
    found = [
        f"{path.relative_to(ROOT)}:{line}: {match.group(0)!r}"
        for path in sorted((ROOT / "pacjax").rglob("*.py"))
        for line, text in _comments_and_docstrings(path)
        for pattern in _HISTORY
        for match in re.finditer(pattern, text)
    ]
    assert not found, "\n".join(found)


def test_the_pattern_finds_a_history(tmp_path):
    sample = tmp_path / "m.py"
    sample.write_text('"""Ran 1,000 rows at 46 eq/s."""\n# 0.91 s against 1.11 s in one pool\n')
    assert len([t for _, t in _comments_and_docstrings(sample)]) == 2
    hits = [p for _, t in _comments_and_docstrings(sample) for p in _HISTORY if re.search(p, t)]
    assert len(hits) == 2


@pytest.mark.slow  # each example compiles its own solves
@pytest.mark.parametrize(
    "example", sorted(p.name for p in (ROOT / "examples").glob("*.py")), ids=lambda n: n[:-3]
)
def test_the_examples_run(example, tmp_path, monkeypatch):
    import runpy
    import sys

    import matplotlib

    matplotlib.use("Agg")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", [example, "--quick"])
    runpy.run_path(str(ROOT / "examples" / example), run_name="__main__")
    assert list(tmp_path.iterdir()), "the example wrote nothing"


def test_the_version_is_the_installed_packages():
    from importlib import metadata

    assert pj.__version__ == metadata.version("pacjax")
    assert "Programming Language :: Python :: 3.13" in metadata.metadata("pacjax").get_all(
        "Classifier"
    )


def test_every_public_name_has_an_api_entry():
    listed = set(re.findall(r"^::: (\S+)$", (ROOT / "docs" / "api.md").read_text(), re.M))
    missing = [
        name
        for name, module in pj._PUBLIC.items()
        if f"pacjax{module}.{name}" not in listed and f"{module}.{name}" not in listed
    ]
    assert not missing, missing
