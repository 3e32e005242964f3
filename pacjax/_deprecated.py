"""Names of earlier releases, kept working for one release with a ``DeprecationWarning``:
module paths (``import pacjax.scenefile`` gives :mod:`pacjax.io.scenefile`) and attributes of
result objects (:func:`warn`)."""

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

#: Old module path -> the module it now is.
MOVED = {
    "pacjax.scenefile": "pacjax.io.scenefile",
    "pacjax.mocapfile": "pacjax.io.mocapfile",
    "pacjax.fitplots": "pacjax.plots.fit",
    "pacjax.animation": "pacjax.plots.animation",
    "pacjax.batchrun": "pacjax.cli.batchrun",
    "pacjax.bench": "pacjax.cli.bench",
}


class _Alias(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds an old path and loads it as the module it moved to (the same module object)."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in MOVED:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec):
        new = MOVED[spec.name]
        warnings.warn(
            f"{spec.name} is deprecated and will be removed: import {new}",
            DeprecationWarning,
            stacklevel=2,
        )
        return importlib.import_module(new)

    def exec_module(self, module):
        pass  # already executed under its new name


def warn(old: str, new: str) -> None:
    """Warn that ``old`` is deprecated in favour of ``new`` (at the caller's caller)."""
    warnings.warn(f"{old} is deprecated and will be removed: use {new}", DeprecationWarning, 3)


def install() -> None:
    """Put the finder on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _Alias) for f in sys.meta_path):
        sys.meta_path.append(_Alias())
