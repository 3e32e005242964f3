"""The package's layers: every import inside pacjax goes downwards, no module takes another's
private (``_``-prefixed) names, and nothing below the interfaces imports matplotlib, click or a
file format. The checks read the source (``ast``), so they see imports inside functions too."""

import ast
import pathlib

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parent.parent / "pacjax"

#: Layers from the bottom up, each a tuple of groups, each group a tuple of module prefixes; a
#: module belongs to the group of its longest matching prefix. A module may import any module of
#: its own group or of a lower layer; the groups of one layer are independent of each other
#: (``_identify`` and ``_inverse`` are separate workflows).
LAYERS = (
    # foundations: float64 at import, numerical configuration, jit, stored traces, the
    # compilation cache, result codes, a root finder, old module paths
    (
        (
            "pacjax._x64",
            "pacjax._config",
            "pacjax._stored",
            "pacjax._jit",
            "pacjax._cache",
            "pacjax._results",
            "pacjax._chord",
            "pacjax._deprecated",
        ),
    ),
    # physics: parameter values, strain fields, kinematics, the body, tendons, loads, energies
    (
        (
            "pacjax._model.values",
            "pacjax._model.trig",
            "pacjax._model.rotation",
            "pacjax._model.quadrature",
            "pacjax._model.strain",
            "pacjax._model.kinematics",
            "pacjax._model.robot",
            "pacjax._model.loads",
            "pacjax._model.tendons",
            "pacjax._model.channels",
            "pacjax._model.energy",
            "pacjax._model.energy_plan",
            "pacjax._model.sites",
            "pacjax._model.layout",
        ),
    ),
    # the scene: assembly, its derivatives, inputs checked against it, queries, presets
    (("pacjax._model", "pacjax.presets"),),
    # solvers
    (("pacjax._statics",),),
    (("pacjax._dynamics", "pacjax.dynamics"),),
    # workflows
    (("pacjax._identify",), ("pacjax._inverse", "pacjax.inverse")),
    # the public namespace
    (("pacjax",),),
    # interfaces
    (("pacjax.io",), ("pacjax.plots",)),
    (("pacjax.cli",),),
)

#: Third-party and standard modules that only the interfaces may import.
INTERFACE_ONLY = ("matplotlib", "click", "tomllib", "tomli_w", "h5py", "csv")
INTERFACES = 7


def _module_name(path: pathlib.Path, root: pathlib.Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _place(module: str) -> tuple[int, int]:
    """(layer, group) of a pacjax module, by its longest matching prefix."""
    best, length = None, -1
    for layer, groups in enumerate(LAYERS):
        for group, prefixes in enumerate(groups):
            for prefix in prefixes:
                if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > length:
                    best, length = (layer, group), len(prefix)
    if best is None:
        raise AssertionError(f"{module} is in no layer of tests/test_architecture.py")
    return best


def _imports(path: pathlib.Path, module: str, is_package: bool, modules: set[str]):
    """(line, imported module, imported name or None) for every import in the file; a name is
    None when it is itself a module (``from . import linalg``)."""
    package = module if is_package else module.rpartition(".")[0]
    tree = ast.parse(path.read_text(), str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name, None
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                if sub in modules:
                    yield node.lineno, sub, None
                else:
                    yield node.lineno, target, alias.name


def _module_aliases(tree: ast.AST, module: str, is_package: bool, modules: set[str]):
    """Local names bound to pacjax modules (``from . import linalg as _linalg``)."""
    package = module if is_package else module.rpartition(".")[0]
    names = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = package.split(".")
            base = base[: len(base) - node.level + 1] if node.level else []
            target = ".".join(base + ([node.module] if node.module else []))
            for alias in node.names:
                if f"{target}.{alias.name}" in modules:
                    names[alias.asname or alias.name] = f"{target}.{alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in modules and alias.asname:
                    names[alias.asname] = alias.name
    return names


def _defined_names(tree: ast.AST) -> set[str]:
    """Every name a module binds: functions, classes and methods, assignments, attributes it
    sets, arguments, imports."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.arg):
            names.add(node.arg)
        elif isinstance(node, ast.alias):
            names.add(node.asname or node.name.split(".")[0])
    return names


def violations(root: pathlib.Path) -> list[str]:
    """Every upward import, cross-module private name and interface-only import under ``root``
    (a package directory), one line each."""
    files = {_module_name(p, root): p for p in sorted(root.rglob("*.py"))}
    modules = set(files)
    found = []
    for module, path in files.items():
        is_package = path.name == "__init__.py"
        layer, group = _place(module)
        for line, target, name in _imports(path, module, is_package, modules):
            where = f"{path.relative_to(root.parent)}:{line}"
            top = target.split(".")[0]
            if top != root.name:
                if layer < INTERFACES and top in INTERFACE_ONLY:
                    found.append(f"{where}: {module} imports {target} (interfaces only)")
                continue
            other_layer, other_group = _place(target)
            upward = other_layer > layer or (other_layer == layer and other_group != group)
            if upward:
                found.append(f"{where}: {module} (layer {layer}) imports {target} (upward)")
            if name and name.startswith("_") and not name.startswith("__") and target != module:
                found.append(f"{where}: {module} imports private {name} from {target}")
        tree = ast.parse(path.read_text())
        aliases = _module_aliases(tree, module, is_package, modules)
        own = _defined_names(tree)
        for node in ast.walk(tree):
            if not (
                isinstance(node, ast.Attribute)
                and node.attr.startswith("_")
                and not node.attr.startswith("__")
            ):
                continue
            where = f"{path.relative_to(root.parent)}:{node.lineno}"
            if isinstance(node.value, ast.Name) and node.value.id in aliases:
                found.append(f"{where}: {module} uses private {aliases[node.value.id]}.{node.attr}")
            elif node.attr not in own:
                # A private attribute this module never defines: another module's (a private
                # method of Scene called from outside, or a library's internals).
                value = ast.unparse(node.value)
                found.append(f"{where}: {module} uses private {node.attr} of {value}")
    return found


def test_pacjax_imports_only_downwards_and_no_private_names():
    found = violations(PACKAGE)
    assert not found, "\n".join(found)


@pytest.mark.parametrize(
    "path, text, expected",
    [
        ("_model/strain.py", "from .._statics.ptc import solve\n", "upward"),
        ("_model/strain.py", "from .scene import Scene\n", "upward"),
        ("_statics/ptc.py", "from .._model.scene import _private\n", "private _private"),
        ("_statics/ptc.py", "from . import linalg\nx = linalg._hidden\n", "private"),
        ("_statics/ptc.py", "import matplotlib.pyplot\n", "interfaces only"),
        ("_statics/ptc.py", "def f(scene):\n    return scene._plan()\n", "private _plan"),
        ("_identify/fit.py", "from .._inverse.problem import solve\n", "upward"),
    ],
)
def test_the_check_finds_each_kind_of_violation(tmp_path, path, text, expected):
    """The check itself, on a small tree with one bad import in it."""
    root = tmp_path / "pacjax"
    for module in ("_model/strain", "_model/scene", "_statics/ptc", "_statics/linalg"):
        (root / module).parent.mkdir(parents=True, exist_ok=True)
        (root / f"{module}.py").write_text("")
    for package in ("", "_model", "_statics", "_inverse", "_identify"):
        (root / package).mkdir(parents=True, exist_ok=True)
        (root / package / "__init__.py").write_text("")
    (root / "_inverse" / "problem.py").write_text("")
    (root / path).write_text(text)
    assert any(expected in v for v in violations(root)), violations(root)
    (root / path).write_text("")
    assert violations(root) == []


def test_the_public_names_import_from_pacjax():
    """SPEC section 3's names, and the result and options objects, from ``import pacjax``."""
    import pacjax as pj

    names = (
        "Segment Robot PCC PAC PolynomialCurvature Tendon Gravity PointMass PointForce "
        "PointMoment Scene presets solve_equilibrium backbone markers solve_batch MocapDataset "
        "identify inverse_statics simulate Equilibrium Equilibria InverseResult Tracking "
        "Trajectory IdentificationReport RESULTS SolverOptions"
    ).split()
    assert [n for n in names if not hasattr(pj, n)] == []
    assert callable(pj.presets.stella2023)


@pytest.mark.parametrize(
    "old, new",
    [
        ("pacjax.scenefile", "pacjax.io.scenefile"),
        ("pacjax.mocapfile", "pacjax.io.mocapfile"),
        ("pacjax.fitplots", "pacjax.plots.fit"),
        ("pacjax.animation", "pacjax.plots.animation"),
        ("pacjax.batchrun", "pacjax.cli.batchrun"),
        ("pacjax.bench", "pacjax.cli.bench"),
    ],
)
def test_moved_modules_import_from_their_old_paths_with_a_warning(old, new):
    import importlib
    import sys

    import pacjax  # noqa: F401  (installs the finder of old paths)

    sys.modules.pop(old, None)
    with pytest.warns(DeprecationWarning, match=f"{old} is deprecated.*import {new}"):
        module = importlib.import_module(old)
    assert module is importlib.import_module(new)
