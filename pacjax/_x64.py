"""Float64 at import without importing JAX (stdlib only).

pacjax solves in float64 by default, so importing it switches on JAX's ``jax_enable_x64``
(``PACJAX_NO_X64=1`` opts out). When JAX is already imported the setting is switched directly.
When it is not, ``JAX_ENABLE_X64=1`` is put in the environment, which JAX reads as it starts: a
user's arrays made before touching pacjax are float64 too, and ``import pacjax`` (and the
command line's ``--help``) need not import JAX. :func:`settle`, called once JAX is imported, puts
the variable back as it was, so child processes do not inherit it.
"""

import os
import sys

#: Whether importing pacjax switches on float64 (``PACJAX_NO_X64`` unset, empty or "0").
X64 = os.environ.get("PACJAX_NO_X64", "").strip().lower() in ("", "0", "false", "no")

_UNSET = object()
#: ``JAX_ENABLE_X64`` as it was before :func:`request` set it (``_UNSET``: not set by pacjax).
_before: object = _UNSET


def request() -> None:
    """Switch float64 on now if JAX is imported, else as JAX starts."""
    global _before
    if not X64:
        return
    if "jax" in sys.modules:
        sys.modules["jax"].config.update("jax_enable_x64", True)
    elif _before is _UNSET:
        _before = os.environ.get("JAX_ENABLE_X64")
        os.environ["JAX_ENABLE_X64"] = "1"


def settle() -> None:
    """Once JAX is imported: make sure float64 is on, and restore ``JAX_ENABLE_X64``."""
    global _before
    if X64:
        sys.modules["jax"].config.update("jax_enable_x64", True)
    if _before is not _UNSET:
        if _before is None:
            os.environ.pop("JAX_ENABLE_X64", None)
        else:
            os.environ["JAX_ENABLE_X64"] = _before
        _before = _UNSET
