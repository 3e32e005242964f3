"""pacjax: differentiable statics of tendon-driven continuum robots (PCC, PAC and polynomial
curvature) in JAX.

The public names load on first use (PEP 562), so that ``import pacjax`` and the ``pacjax``
command line's ``--help`` do not pay for importing JAX. Float64 is still switched on at import:
see :mod:`pacjax._x64`.
"""

import importlib
from importlib import metadata

from . import _deprecated, _x64  # standard library only

try:
    __version__ = metadata.version("pacjax")  # pyproject.toml's, as installed
except metadata.PackageNotFoundError:  # a source tree on sys.path, not installed
    __version__ = "0+unknown"

_x64.request()
_deprecated.install()

#: Public name -> the module that defines it (relative to this package).
_PUBLIC = {
    "Gravity": "._model.loads",
    "PointForce": "._model.loads",
    "PointMass": "._model.loads",
    "PointMoment": "._model.loads",
    "ExponentialStiffening": "._model.robot",
    "Robot": "._model.robot",
    "Segment": "._model.robot",
    "SectionProfile": "._model.robot",
    "StiffeningLaw": "._model.robot",
    "Scene": "._model.scene",
    "PAC": "._model.strain",
    "PCC": "._model.strain",
    "PolynomialCurvature": "._model.strain",
    "StrainModel": "._model.strain",
    "Tendon": "._model.tendons",
    "RESULTS": "._results",
    "MocapDataset": "._identify.dataset",
    "static_frames": "._identify.dataset",
    "identify": "._identify.identify",
    "IdentificationReport": "._identify.report",
    "Branches": "._identify.branches",
    "high_fidelity": "._identify.synthetic",
    "synthetic_mocap": "._identify.synthetic",
    "astype": "._model.query",
    "backbone": "._model.query",
    "markers": "._model.query",
    "tendon_tensions": "._model.query",
    "tip_pose": "._model.query",
    "iter_batch": "._statics.batch",
    "solve_batch": "._statics.batch",
    "solve_equilibrium": "._statics.equilibrium",
    "Equilibria": "._statics.multistart",
    "find_equilibria": "._statics.multistart",
    "SolverOptions": "._statics.options",
    "SparseRingsWarning": "._statics.ringcheck",
    "Equilibrium": "._statics.solution",
    "Damping": ".dynamics",
    "Trajectory": ".dynamics",
    "simulate": ".dynamics",
    "simulate_batch": ".dynamics",
    "InverseResult": ".inverse",
    "Tracking": ".inverse",
    "Workspace": ".inverse",
    "inverse_statics": ".inverse",
    "inverse_statics_batch": ".inverse",
    "sample_workspace": ".inverse",
    "track": ".inverse",
    "enable_compilation_cache": "._cache",
}
#: Public submodules, loaded on first use like the names.
_SUBMODULES = ("dynamics", "inverse", "presets", "io", "plots")

__all__ = sorted([*_PUBLIC, *_SUBMODULES, "__version__"])


def __getattr__(name: str):
    if name not in _PUBLIC and name not in _SUBMODULES:
        raise AttributeError(f"module 'pacjax' has no attribute {name!r}")
    importlib.import_module("._config", __name__)  # JAX up, float64 on, before any pacjax module
    if name in _PUBLIC:
        value = getattr(importlib.import_module(_PUBLIC[name], __name__), name)
    else:
        value = importlib.import_module(f".{name}", __name__)
    globals()[name] = value
    return value


def __dir__():
    return sorted({*globals(), *__all__})
