"""Traced programs kept on disk beside the compilation cache, so that a new process skips
tracing as well as compiling.

JAX's persistent compilation cache keys an executable by its lowered program: to find the
executable, a new process must first trace the Python code and lower it, and on pacjax's solver
programs that is most of a first call once XLA's part comes from the cache (seconds per entry
point, ``benchmarks/RESULTS.md``). When that cache is on, a top-level call of a pacjax program
(:func:`pacjax._jit.jit`) is therefore made through :mod:`jax.export`: the program is traced
and lowered once, serialised into ``<cache directory>/pacjax-programs``, and a later process
with the same program loads it and calls it without tracing (XLA's executable then comes from
the compilation cache as before).

A stored program is found by a key that holds everything that decides what is traced: the
function's name, the digest of pacjax's source files, the jax and jaxlib versions, the backend
and compile options, float64 on or off, and the arguments' structure, static values (printed
in full: a printed array is not abbreviated) and array shapes, dtypes and weak types. Arguments
whose static values print with a memory address (a function, an object without a ``repr``), or
that live on another device than the default one, are not keyed: such calls trace as before. A
damaged or unreadable entry is skipped with a warning and written again; a program that
:mod:`jax.export` cannot serialise is traced as before (its first call in a process traces it
twice).

The store trusts that the code it traced is pacjax's source as installed: a program whose
functions are replaced at run time (a test's monkeypatch) would load the trace of the
originals, so such code runs with ``PACJAX_STORED_PROGRAMS=0`` (the test suite does).
Entries of other pacjax sources are removed as a new program is written (two installations
that share a cache take turns). Entries hold a pickled example of the output's structure: the
directory is the user's own, as the compilation cache's executables are.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import os
import pickle
import re
import sys
import tempfile
import threading
import time
import warnings
from pathlib import Path

import equinox as eqx
import jax
import numpy as np

#: Programs that traced and lowered faster than this (s) are kept in memory, not on disk (a
#: program of 0.1 s, a fit's marker predictions, loads from disk faster than it traces).
MIN_TRACE_TIME_S = 0.05

#: A printed static value that names a memory address cannot key a program across processes.
_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")

_PLAIN = object()  # memo value: trace this call as before
_memo: dict = {}
_lock = threading.Lock()


#: ``PACJAX_STORED_PROGRAMS=0`` turns stored programs off (the compilation cache stays on).
ENVIRONMENT = "PACJAX_STORED_PROGRAMS"


def directory() -> Path | None:
    """Where programs are stored: beside JAX's compilation cache; None when it is off, or
    when ``PACJAX_STORED_PROGRAMS`` is ``0``."""
    cache = jax.config.jax_compilation_cache_dir
    if not cache or os.environ.get(ENVIRONMENT, "1").strip().lower() in ("0", "off", "false", "no"):
        return None
    return Path(cache) / "pacjax-programs"


@functools.cache
def source_digest() -> str:
    """A digest of pacjax's Python sources: an edited pacjax never loads an older trace."""
    root = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


@functools.cache
def _versions() -> str:
    try:
        jaxlib = importlib.metadata.version("jaxlib")
    except importlib.metadata.PackageNotFoundError:
        jaxlib = "unknown"
    return f"jax {jax.__version__} jaxlib {jaxlib}"


def _aval(x) -> tuple:
    dtype = x.dtype if hasattr(x, "dtype") else np.result_type(x)
    return (tuple(np.shape(x)), str(dtype), bool(getattr(x, "weak_type", False)))


def _on_default_device(x, device) -> bool:
    sharding = getattr(x, "sharding", None)
    return sharding is None or sharding.device_set == {device}


class _Program:
    """A loaded program: its compiled call and how its flat outputs become the result."""

    def __init__(self, call, out_def, out_static):
        self.call, self.out_def, self.out_static = call, out_def, out_static

    def __call__(self, leaves):
        outs = self.call(*leaves)
        return eqx.combine(jax.tree.unflatten(self.out_def, outs), self.out_static)


def call_stored(fn, options: dict, args: tuple, kwargs: dict):
    """``fn(*args, **kwargs)`` through its stored program; ``NotImplemented`` where this call
    is not stored (the caller then traces it as before)."""
    folder = directory()
    if folder is None or getattr(fn, "__closure__", None):  # a closure's cells are not keyed
        return NotImplemented
    dynamic, static = eqx.partition((args, kwargs), eqx.is_array)
    leaves, treedef = jax.tree.flatten(dynamic)
    device = jax.devices()[0]
    if jax.config.jax_default_device is not None or not all(
        _on_default_device(x, device) for x in leaves
    ):
        return NotImplemented
    static_leaves, static_def = jax.tree.flatten(static)
    avals = tuple(_aval(x) for x in leaves)
    signature = (fn, folder, tuple(options.items()), treedef, static_def, tuple(static_leaves))
    try:
        signature = (*signature, avals)
        hash(signature)
    except TypeError:  # an unhashable static value: the program is found by its key alone
        signature = None
    program = _memo.get(signature) if signature is not None else None
    if program is None:
        key = _key(fn, options, static_def, static_leaves, treedef, avals)
        if key is None:
            program = _PLAIN
        else:
            program = _memo.get((folder, key)) or _program(
                fn, options, folder, key, (static, treedef, avals)
            )
            with _lock:
                _memo[(folder, key)] = program
        if signature is not None:
            with _lock:
                _memo[signature] = program
    if program is _PLAIN:
        return NotImplemented
    return program(leaves)


def _key(fn, options, static_def, static_leaves, treedef, avals) -> str | None:
    """The program's key; None where a static value prints with a memory address. The
    structures print their nodes' static fields with the values' own ``repr`` (a module's
    pretty-printed ``repr`` would show an array by its shape)."""
    with np.printoptions(threshold=sys.maxsize, floatmode="unique"):
        text = "\n".join(
            [
                f"{fn.__module__}.{fn.__qualname__}",
                source_digest(),
                _versions(),
                jax.default_backend(),
                repr(sorted(options.items())),
                str(jax.config.jax_enable_x64),
                str(jax.config.jax_default_matmul_precision),
                repr(treedef),
                repr(avals),
                repr(static_def),
                repr(static_leaves),
            ]
        )
    if _ADDRESS.search(text):
        return None
    return hashlib.sha256(text.encode()).hexdigest()


def _program(fn, options, folder: Path, key: str, inputs):
    path = folder / f"{fn.__name__}-{source_digest()[:12]}-{key[:32]}.bin"
    if path.exists():
        try:
            exported, skeleton = _read(path)
            return _loaded(fn.__name__, exported, skeleton, options)
        except Exception as exc:  # a damaged entry must never stop a solve
            warnings.warn(
                f"pacjax: skipped the stored program {path.name} ({type(exc).__name__}: {exc}); "
                "it is traced and written again",
                RuntimeWarning,
                stacklevel=4,
            )
    start = time.perf_counter()
    try:
        exported, skeleton = _export(fn, *inputs)
    except Exception:
        # What jax.export cannot serialise (a host callback, an unregistered custom call)
        # still runs traced.
        return _PLAIN
    if time.perf_counter() - start >= MIN_TRACE_TIME_S:
        _write(path, exported, skeleton)
    return _loaded(fn.__name__, exported, skeleton, options)


def _export(fn, static, treedef, avals):
    found = {}

    def flat(*xs):
        args, kwargs = eqx.combine(jax.tree.unflatten(treedef, xs), static)
        out_dynamic, out_static = eqx.partition(fn(*args, **kwargs), eqx.is_array)
        outs, out_def = jax.tree.flatten(out_dynamic)
        examples = [np.zeros(o.shape, o.dtype) for o in outs]
        found["skeleton"] = eqx.combine(jax.tree.unflatten(out_def, examples), out_static)
        return outs

    specs = [jax.ShapeDtypeStruct(s, np.dtype(d), weak_type=w) for s, d, w in avals]
    # Custom calls (LAPACK's) need no compatibility across versions: an entry is only ever
    # read by the jaxlib that wrote it (the key holds its version).
    any_custom_call = jax.export.DisabledSafetyCheck.custom_call("ALL")
    exported = jax.export.export(jax.jit(flat), disabled_checks=[any_custom_call])(*specs)
    return exported, found["skeleton"]


def _loaded(name: str, exported, skeleton, options) -> _Program:
    out_dynamic, out_static = eqx.partition(skeleton, eqx.is_array)

    def run(*leaves):
        return exported.call(*leaves)

    run.__name__ = run.__qualname__ = name  # profiles and compile logs name the program
    # Inputs and outputs on the default device, whether an array arrives committed (a previous
    # call's output) or not (NumPy's): otherwise the two lower differently and compile twice.
    device = jax.sharding.SingleDeviceSharding(jax.devices()[0])
    call = jax.jit(run, in_shardings=device, out_shardings=device, compiler_options=options)
    return _Program(call, jax.tree.structure(out_dynamic), out_static)


@functools.cache
def _forget_older_sources(folder: Path) -> None:
    """Entries of other pacjax sources are never loaded again: removed (once per process), so
    that editing pacjax does not grow the folder by a program set per edit."""
    for path in folder.glob("*.bin"):
        if f"-{source_digest()[:12]}-" not in path.name:
            path.unlink(missing_ok=True)


def _read(path: Path):
    with open(path, "rb") as f:
        blob, skeleton = pickle.load(f)
    return jax.export.deserialize(bytearray(blob)), skeleton


def _write(path: Path, exported, skeleton) -> None:
    """Written whole or not at all (a killed process leaves no half-written entry)."""
    try:
        payload = pickle.dumps((exported.serialize(), skeleton))
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            f.write(payload)
        os.replace(tmp, path)
        _forget_older_sources(path.parent)
    except Exception as exc:  # a full disk or an unpicklable result: the call still runs
        warnings.warn(
            f"pacjax: could not store the program {path.name} ({type(exc).__name__}: {exc})",
            RuntimeWarning,
            stacklevel=5,
        )
