"""Parameter values as the model takes them: converted to float arrays, read when known before
tracing, and checked with one-line errors that name the field."""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array


def as_float(x, name: str = "parameter") -> Array:
    """A parameter as a float array (float64 unless the value already is a float32 array).

    Raises a TypeError naming ``name`` for anything that is not real numbers (a string, None,
    a boolean, a complex number), instead of numpy's anonymous conversion error.
    """
    if isinstance(x, (jnp.ndarray, np.ndarray)):
        if jnp.issubdtype(x.dtype, jnp.floating):
            return jnp.asarray(x)
        if not (jnp.issubdtype(x.dtype, jnp.integer) and x.dtype != bool):
            raise TypeError(f"{name} must be real numbers, got an array of dtype {x.dtype}")
        return jnp.asarray(x, dtype=float)
    if isinstance(x, (bool, np.bool_)) or x is None or np.iscomplexobj(x):
        raise TypeError(f"{name} must be a real number, got {x!r}")
    try:
        arr = np.asarray(x)
    except (TypeError, ValueError) as err:  # ragged nesting
        raise TypeError(f"{name} must be a real number or an array of them, got {x!r}") from err
    if arr.dtype == bool or not (
        jnp.issubdtype(arr.dtype, jnp.floating) or jnp.issubdtype(arr.dtype, jnp.integer)
    ):
        raise TypeError(f"{name} must be a real number or an array of them, got {x!r}")
    return jnp.asarray(arr, dtype=float)


def float_field(name: str):
    """An ``eqx.field`` converter that makes a float array and names the field on bad input."""

    def convert(x):
        return as_float(x, name)

    return convert


def concrete(x) -> np.ndarray | None:
    """``x`` as a numpy array when its value is known now (not a tracer), else None."""
    try:
        return np.asarray(x, dtype=float)
    except Exception:  # a tracer inside jit / vmap: checks run before tracing instead
        return None


def known_sites(values, dtype):
    """Point sites ``s`` along segments: a numpy array when every one is known now, else a
    traced array. Known sites take the knot path of the kinematics (``Scene.frames``); a ``jnp``
    op inside ``jit`` would make even Python floats traced and send them down the grid path."""
    known = concrete(values)  # None when any of them is traced
    if known is not None and known.shape == (len(values),):
        return known
    return jnp.stack([jnp.asarray(v) for v in values]).astype(dtype)


def check_scalar(name: str, value) -> None:
    """Raise a ValueError naming ``name`` unless ``value`` is a single number."""
    if jnp.shape(value) != ():
        raise ValueError(f"{name} must be a single number, got shape {jnp.shape(value)}")


def check_positive(name: str, value, allow_zero: bool = False) -> None:
    """Raise a ValueError naming ``name`` unless every entry of ``value`` is finite and > 0."""
    v = concrete(value)
    if v is None:
        return
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {v}")
    if allow_zero and np.any(v < 0):
        raise ValueError(f"{name} must be >= 0, got {v}")
    if not allow_zero and np.any(v <= 0):
        raise ValueError(f"{name} must be > 0, got {v}")


def check_finite(name: str, value) -> None:
    v = concrete(value)
    if v is not None and not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {v}")
