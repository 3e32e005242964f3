"""JAX's persistent compilation cache, in a directory of its own per jaxlib and processor.

Compiling a solver dominates a first run; the cache keeps compiled programs on disk between
processes. JAX keys each entry by the program, the jaxlib version, the backend and the XLA flags,
but not by the host processor, and an XLA:CPU executable is machine code for the processor that
compiled it (AVX-512 or not, ...): a cache directory shared by two machines (a home directory on
a cluster, a copied ``~/.cache``) could hand one of them code it cannot run. The directory used
here is therefore ``ROOT/jaxlib-<version>-<machine>-<processor hash>``, so that a cache written
by another jaxlib or processor is never read.

What happens to damaged entries: JAX compresses every entry with a checksum (zlib's adler32, or
zstd's frame checksum) and turns an entry that fails to decompress (truncated by a killed
process, a half-written file, bit rot) into a warning and a fresh compile. What it cannot turn
into a warning is a crash inside XLA while it deserializes an intact entry: loading an
executable of thousands of kernels overflowed a fixed-size linker thread stack on jaxlib 0.9
(reported by other JAX users), and such a crash is a signal, not an exception. The cache is
therefore opt-in for library users, and entries are only written for programs that took at least
``min_compile_time_s`` to compile. A run that crashed while loading from the cache can be
repeated with ``PACJAX_CACHE_DIR=off`` (the command line) or without the call; deleting the
directory empties it.

JAX does not store a program that calls back into Python, and diffrax checks a simulation's
save times with equinox's runtime errors, which are such callbacks: with them every
``pj.simulate`` compiles again in each new process. With ``EQX_ON_ERROR=nan`` (read by equinox
as it is imported) those checks become a NaN in place of the error and the program is stored;
pacjax checks the save times and the first step itself before compiling, and reads a failed
integration from its result code, not from an exception. The command
line sets it for its own process (:func:`enable_from_environment`); a library user sets it in
the environment to have simulations stored too.

This module imports only the standard library: the command line enables the cache before JAX
is imported, through the environment variables JAX reads as it starts.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import os
import platform
import sys
from pathlib import Path

#: Where caches live unless told otherwise (``PACJAX_CACHE_DIR`` for the command line).
DEFAULT_ROOT = Path("~", ".cache", "pacjax-jax")

#: Values of ``PACJAX_CACHE_DIR`` that turn the command line's cache off.
OFF = ("", "off", "none", "0", "false", "no")


def processor_id() -> str:
    """A short hash of what the host processor can run: its model and instruction-set flags
    (``/proc/cpuinfo`` on Linux, ``platform.processor()`` elsewhere)."""
    text = platform.processor()
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            lines = f.read().split("\n\n", 1)[0].splitlines()
        keep = ("vendor_id", "model name", "flags", "Features", "CPU implementer", "CPU part")
        text = "\n".join(line for line in lines if line.split(":", 1)[0].strip() in keep)
    except OSError:
        pass
    return hashlib.sha256(f"{platform.machine()}\n{text}".encode()).hexdigest()[:12]


def cache_directory(root: str | os.PathLike | None = None) -> Path:
    """The cache directory for this jaxlib and processor under ``root`` (default
    ``~/.cache/pacjax-jax``)."""
    try:
        jaxlib = importlib.metadata.version("jaxlib")
    except importlib.metadata.PackageNotFoundError:
        jaxlib = "unknown"
    name = f"jaxlib-{jaxlib}-{platform.machine()}-{processor_id()}"
    return Path(root if root is not None else DEFAULT_ROOT).expanduser() / name


def enable_compilation_cache(
    root: str | os.PathLike | None = None, *, min_compile_time_s: float = 0.05
) -> Path:
    """Keep compiled programs on disk between processes (JAX's persistent compilation cache).

    Args:
        root: folder for the caches; the one used is a subfolder named after the jaxlib
            version and the processor (see :func:`cache_directory`). Default
            ``~/.cache/pacjax-jax``.
        min_compile_time_s: programs that compiled faster than this are not written. JAX's
            own default, 1 s, left out pacjax programs of 0.3-1 s (a fit's evaluation, the
            batch's starting points, the ring check's 0.1 s), compiled again by every new
            process; below 0.05 s are the single operations run outside a program (5-25 ms
            each).

    Returns:
        The cache directory.

    Call it before the first solve. The command line enables it by default
    (``PACJAX_CACHE_DIR=DIR`` moves it, ``PACJAX_CACHE_DIR=off`` turns it off). With it on,
    pacjax also keeps its traced programs in the directory's ``pacjax-programs`` folder, so
    that a new process skips tracing as well as compiling (``PACJAX_STORED_PROGRAMS=0`` turns
    that part off).
    """
    if not min_compile_time_s >= 0:
        raise ValueError(f"min_compile_time_s must be >= 0, got {min_compile_time_s}")
    directory = cache_directory(root)
    directory.mkdir(parents=True, exist_ok=True)
    if "jax" in sys.modules:
        config = sys.modules["jax"].config
        config.update("jax_compilation_cache_dir", str(directory))
        config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_time_s))
    else:  # read by JAX as it starts
        os.environ["JAX_COMPILATION_CACHE_DIR"] = str(directory)
        os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = str(float(min_compile_time_s))
    return directory


def enable_from_environment() -> Path | None:
    """The command line's default: the cache under ``$PACJAX_CACHE_DIR`` (default
    ``~/.cache/pacjax-jax``), or none when it is ``off``; an unusable folder is a warning.
    Unless the environment says otherwise, equinox's runtime errors become NaN
    (``EQX_ON_ERROR=nan``, see the module) so that simulations are stored too."""
    root = os.environ.get("PACJAX_CACHE_DIR", str(DEFAULT_ROOT))
    if root.strip().lower() in OFF:
        return None
    os.environ.setdefault("EQX_ON_ERROR", "nan")
    try:
        return enable_compilation_cache(root)
    except OSError as err:
        print(f"pacjax: compilation cache off ({err})", file=sys.stderr)
        return None
