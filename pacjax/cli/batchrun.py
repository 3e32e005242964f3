"""Many equilibria of one scene: sample commands, solve them chunk by chunk, write a columnar file.

The engine of ``pacjax batch``; every step is a plain function so that scripts can use them too:

- :func:`default_ranges`: command ranges from a scene's tendons;
- :func:`sample_commands`: uniform, Latin-hypercube (``scipy.stats.qmc``) or grid samples;
- :func:`run_batch`: solves with :func:`pacjax.iter_batch` and writes every chunk to an HDF5
  file (:class:`BatchWriter`) as soon as it is solved, so memory is bounded by the chunk size;
- :func:`read_batch` and :func:`plot_workspace`: read the file back, plot the tip positions.

The file (HDF5, one dataset per column, row ``i`` = command ``i``):

=================  ================  ==========================================================
``commands``       (n, n_tendons)    tendon commands (m pull-in, or N tension)
``q``              (n, n_dofs)       equilibrium coordinates (attribute ``names``)
``markers``        (n, n_sites, 3)   marker positions (m), only for scenes with ``markers``
``tip_position``   (n, 3)            tip position (m), world frame
``tip_rotation``   (n, 3, 3)         tip rotation matrix, tip frame to world frame
``converged``      (n,)              bool
``stable``         (n,)              bool (False at a saddle)
``residual_norm``  (n,)              scaled residual (see :class:`pacjax.Equilibrium`)
``steps``          (n,)              solver steps
``result``         (n,)              index of the :class:`pacjax.RESULTS` item (0 successful)
=================  ================  ==========================================================

File attributes: ``scene_toml`` (the scene file's text, when given), ``sampler``, ``seed``,
``low``, ``high``, ``dtype``, ``tol``, ``pacjax_version``, and ``rows_written`` (rows complete
so far; a run that was interrupted leaves a readable prefix).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import resource
import signal
import sys
import threading
import time
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

import pacjax as pj

from .._jit import jit
from .._model.inputs import check_scene
from .._results import code_of

SAMPLERS = ("uniform", "lhs", "grid")

#: Default pull-in range of a length-mode tendon, as a fraction of the rest length of the
#: segments it spans (its own segment for a Bowden tendon, base to anchor for a free one).
PULL_IN_FRACTION = 0.15
#: Default tension range of a tension-mode tendon: the tension whose moment ``T r`` alone would
#: bend its anchor segment by this angle (rad), ``T = EI angle / (L r)``.
TENSION_BEND_ANGLE = math.pi / 2


# ------------------------------------------------------------------------------ sampling
def default_ranges(scene: pj.Scene) -> tuple[np.ndarray, np.ndarray]:
    """``(low, high)`` command ranges from the scene's tendons: zero up to
    :data:`PULL_IN_FRACTION` of the spanned length for length-mode tendons (m), zero up to the
    tension that bends the anchor segment by :data:`TENSION_BEND_ANGLE` for tension-mode ones
    (N)."""
    check_scene(scene)
    if scene.n_tendons == 0:
        raise ValueError("the scene has no tendons: there are no commands to sample")
    lengths = [float(seg.length) for seg in scene.robot.segments]
    high = []
    for t in scene.tendons:
        own = lengths[t.segment] * t.s
        if t.mode == "length":
            spanned = own if t.bowden else sum(lengths[: t.segment]) + own
            high.append(PULL_IN_FRACTION * spanned)
        else:
            seg = scene.robot.segments[t.segment]
            high.append(
                float(seg.bending_stiffness)
                * TENSION_BEND_ANGLE
                / (lengths[t.segment] * float(t.offset))
            )
    high = np.asarray(high)
    return np.zeros_like(high), high


def check_ranges(low, high, n_tendons: int) -> tuple[np.ndarray, np.ndarray]:
    """``low`` and ``high`` as ``(n_tendons,)`` arrays (a scalar applies to every tendon);
    raises :class:`ValueError` naming the field when a shape or value is wrong."""
    out = []
    for name, value in (("low", low), ("high", high)):
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be numbers, got {value!r}") from None
        if arr.ndim == 0:
            arr = np.full(n_tendons, float(arr))
        if arr.shape != (n_tendons,):
            raise ValueError(
                f"{name} must be one number or one per tendon ({n_tendons} values), "
                f"got shape {arr.shape}"
            )
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite, got {arr.tolist()}")
        out.append(arr)
    low, high = out
    bad = np.flatnonzero(low > high)
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"low must be <= high for every tendon; tendon {i}: {low[i]} > {high[i]}")
    return low, high


def grid_points_per_axis(n: int, n_tendons: int) -> int:
    """Points per tendon of the largest full grid with at most ``n`` rows."""
    k = int(math.floor(n ** (1.0 / n_tendons) + 1e-9))
    while (k + 1) ** n_tendons <= n:
        k += 1
    while k > 1 and k**n_tendons > n:
        k -= 1
    return k


def sample_commands(sampler: str, n: int, low, high, seed: int = 0) -> np.ndarray:
    """Commands ``(rows, n_tendons)`` between ``low`` and ``high`` (arrays, one per tendon).

    ``uniform``: ``n`` independent uniform rows. ``lhs``: ``n`` rows of a Latin hypercube
    (every tendon's range cut into ``n`` equal strata, one sample in each). ``grid``: the full
    grid with ``k = floor(n ** (1 / n_tendons))`` evenly spaced values per tendon (ends
    included), ``k ** n_tendons <= n`` rows; needs ``k >= 2``.
    """
    if sampler not in SAMPLERS:
        raise ValueError(f"sampler must be one of {', '.join(SAMPLERS)}; got {sampler!r}")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise TypeError(f"n must be an integer, got {n!r}")
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    low = np.asarray(low, float)
    high = np.asarray(high, float)
    m = low.shape[0]
    if sampler == "uniform":
        return np.random.default_rng(seed).uniform(low, high, (n, m))
    if sampler == "lhs":
        from scipy.stats import qmc

        try:
            lhs = qmc.LatinHypercube(d=m, rng=np.random.default_rng(seed))
        except TypeError:  # scipy < 1.15 names it seed
            lhs = qmc.LatinHypercube(d=m, seed=np.random.default_rng(seed))
        unit = lhs.random(n)
        return low + unit * (high - low)
    k = grid_points_per_axis(n, m)
    if k < 2:
        raise ValueError(
            f"a grid over {m} tendons needs n >= 2**{m} = {2**m} (2 values per tendon), got {n}"
        )
    axes = [np.linspace(lo, hi, k) for lo, hi in zip(low, high, strict=True)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, m)


# ------------------------------------------------------------------------------ outputs
@jit
def _pose_and_markers(scene, q):
    def one(qi):
        tip, rot = pj.tip_pose(scene, qi)
        sites = pj.markers(scene, qi) if scene.markers else None
        return tip, rot, sites

    return jax.vmap(one)(q)


def chunk_columns(scene: pj.Scene, commands: np.ndarray, eq: pj.Equilibrium) -> dict:
    """The file's columns for one solved chunk (numpy arrays, leading axis = rows)."""
    tip, rot, sites = _pose_and_markers(scene, jnp.asarray(eq.q))
    columns = {
        "commands": np.asarray(commands, float),
        "q": np.asarray(eq.q),
        "tip_position": np.asarray(tip),
        "tip_rotation": np.asarray(rot),
        "converged": np.asarray(eq.converged, bool),
        "stable": np.asarray(eq.stable, bool),
        "residual_norm": np.asarray(eq.residual_norm),
        "steps": np.asarray(eq.steps, np.int32),
        "result": code_of(eq.result).astype(np.int8),
    }
    if sites is not None:
        columns["markers"] = np.asarray(sites)
    return columns


class BatchWriter:
    """An HDF5 file with one preallocated dataset per column, filled chunk by chunk.

    Use as a context manager; :meth:`write` stores the rows of one chunk. The file stays
    readable and resumable whenever the process stops, even by ``SIGKILL``: every dataset's
    space is allocated when the file is made (a write then changes raw data only, never the
    file's structure), and each chunk's rows are flushed to the file before the
    ``rows_written`` attribute that counts them, which is flushed next. ``resume=True`` opens
    an existing file instead and continues after its ``rows_written`` rows.
    """

    def __init__(
        self,
        path: str,
        scene: pj.Scene,
        n: int,
        attrs: dict | None = None,
        chunk_rows: int = 1024,
        resume: bool = False,
    ):
        import h5py

        self.path = path
        self.n = n
        if resume:
            self.file = h5py.File(path, "r+")
            self.rows_written = int(self.file.attrs["rows_written"])
            return
        self.file = h5py.File(path, "w")
        dtype = np.dtype(jnp.asarray(scene.robot.segments[0].length).dtype)
        rows = max(1, min(chunk_rows, n))
        shapes = {
            "commands": ((scene.n_tendons,), np.float64),
            "q": ((scene.n_dofs,), dtype),
            "tip_position": ((3,), dtype),
            "tip_rotation": ((3, 3), dtype),
            "converged": ((), np.bool_),
            "stable": ((), np.bool_),
            "residual_norm": ((), dtype),
            "steps": ((), np.int32),
            "result": ((), np.int8),
        }
        if scene.markers:
            shapes["markers"] = ((len(scene.markers), 3), dtype)
        for name, (shape, dt) in shapes.items():
            dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
            dcpl.set_alloc_time(h5py.h5d.ALLOC_TIME_EARLY)
            self.file.create_dataset(
                name, (n, *shape), dtype=dt, chunks=(rows, *shape), fillvalue=0, dcpl=dcpl
            )
        self.file["q"].attrs["names"] = list(scene.coordinate_names())
        if scene.markers:
            self.file["markers"].attrs["sites"] = np.asarray(
                [[seg, s, *offset] for seg, s, offset in scene.markers], float
            )
        for key, value in (attrs or {}).items():
            self.file.attrs[key] = value
        self.file.attrs["rows_written"] = 0
        self.file.attrs["pacjax_version"] = pj.__version__
        self.file.flush()
        self.rows_written = 0

    def write(self, rows: slice, columns: dict) -> None:
        for name, values in columns.items():
            self.file[name][rows] = values
        self.file.flush()  # the rows first, then the count that makes them part of the file
        self.rows_written = max(self.rows_written, rows.stop)
        self.file.attrs["rows_written"] = self.rows_written
        self.file.flush()

    def close(self) -> None:
        self.file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def read_batch(path: str, columns=None, rows: slice | None = None) -> dict:
    """Columns of a batch file as numpy arrays (all by default; ``rows`` selects a range)."""
    import h5py

    with h5py.File(path, "r") as f:
        names = list(f.keys()) if columns is None else list(columns)
        sel = slice(None) if rows is None else rows
        out = {name: f[name][sel] for name in names}
        out["attrs"] = dict(f.attrs)
    return out


# ------------------------------------------------------------------------------ running
@dataclasses.dataclass
class BatchSummary:
    """What :func:`run_batch` measured."""

    n: int
    converged: int
    stable: int
    wall_s: float
    first_chunk_s: float  # includes compiling the solver and the output kernels
    chunks: int
    chunk_size: int
    peak_memory_mib: float
    max_residual_converged: float
    #: Peak memory in use on the accelerator(s), the largest over the local devices (MiB);
    #: None where the backend does not report it (the CPU).
    peak_device_memory_mib: float | None = None
    #: Rows an interrupted run had written to the file before this one resumed it.
    resumed_rows: int = 0

    @property
    def converged_fraction(self) -> float:
        return self.converged / self.n

    @property
    def equilibria_per_s(self) -> float:
        """The rows solved in this run over its whole wall time (compilation included)."""
        return (self.n - self.resumed_rows) / self.wall_s

    @property
    def warm_equilibria_per_s(self) -> float | None:
        """Rows after the first chunk over their wall time (None with a single chunk)."""
        rest = self.wall_s - self.first_chunk_s
        rows = self.n - self.resumed_rows - min(self.chunk_size, self.n)
        return rows / rest if rows > 0 and rest > 0 else None

    def as_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d.update(
            converged_fraction=self.converged_fraction,
            equilibria_per_s=self.equilibria_per_s,
            warm_equilibria_per_s=self.warm_equilibria_per_s,
        )
        return d

    def lines(self) -> list[str]:
        warm = self.warm_equilibria_per_s
        resumed = (
            f" ({self.resumed_rows} of them from the run resumed)" if self.resumed_rows else ""
        )
        return [
            f"n = {self.n}{resumed}, converged {self.converged} ({self.converged_fraction:.2%}), "
            f"stable {self.stable}",
            f"wall {self.wall_s:.2f} s ({self.chunks} chunk(s) of {self.chunk_size}); first chunk "
            f"{self.first_chunk_s:.2f} s (compilation included)",
            f"equilibria/s: {self.equilibria_per_s:.1f} overall"
            + (f", {warm:.1f} after the first chunk" if warm else ""),
            f"largest residual of a converged row: {self.max_residual_converged:.2e}",
            f"peak memory (max RSS): {self.peak_memory_mib:.0f} MiB"
            + (
                f", on the accelerator {self.peak_device_memory_mib:.0f} MiB"
                if self.peak_device_memory_mib is not None
                else ""
            ),
        ]


def peak_memory_mib() -> float:
    """Peak resident memory of this process (MiB), from ``resource.getrusage``."""
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / 2**20 if sys.platform == "darwin" else rss / 2**10  # bytes on macOS, KiB on Linux


def peak_device_memory_mib() -> float | None:
    """Peak memory in use on this process's devices (MiB, the largest device), from
    ``jax.Device.memory_stats``; None where no device reports it (XLA:CPU reports nothing)."""
    peaks = []
    for device in jax.local_devices():
        stats = device.memory_stats() or {}
        if "peak_bytes_in_use" in stats:
            peaks.append(stats["peak_bytes_in_use"] / 2**20)
    return max(peaks) if peaks else None


@contextlib.contextmanager
def _interrupts():
    """``check()``: raise ``KeyboardInterrupt`` after a chunk if Ctrl-C came during it.

    Python raises Ctrl-C's ``KeyboardInterrupt`` wherever the main thread is; inside a weakref
    callback or a finaliser (the solver and h5py run many) it is printed and dropped, and a
    batch went on to its end. The handler also records the signal, so the next chunk boundary
    stops the run. A SIGINT that is ignored or handled by the caller is left as it is.
    """
    seen = []

    def handler(signum, frame):
        seen.append(signum)
        raise KeyboardInterrupt

    def check():
        if seen:
            raise KeyboardInterrupt

    main = threading.current_thread() is threading.main_thread()
    if not main or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield lambda: None
        return
    signal.signal(signal.SIGINT, handler)
    try:
        yield check
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def run_batch(
    scene: pj.Scene,
    commands: np.ndarray,
    path: str,
    *,
    chunk_size: int = 1024,
    attrs: dict | None = None,
    on_chunk: Callable[[int], None] | None = None,
    on_rows: Callable[[int], None] | None = None,
    resume: bool = False,
    **solver_options,
) -> BatchSummary:
    """Solve every row of ``commands`` with :func:`pacjax.iter_batch` and write each chunk to
    the HDF5 file ``path`` as it finishes (see the module doc for the columns).

    ``on_chunk(rows)`` is called after each chunk is written, ``on_rows(rows)`` as rows leave
    the solver's slot pool (a progress bar that moves row by row). ``solver_options``
    go to the solver (``tol``, ``max_steps``, ``warm_start``, ``fallback``, ...).

    ``resume=True`` continues a file that an interrupted run with the same ``commands`` and
    ``chunk_size`` left: its first ``rows_written`` rows are kept (and counted in the summary),
    and the rest are solved in the same chunks as an uninterrupted run would have solved them,
    so the file ends the same. Raises :class:`ValueError` when the file holds other commands.
    """
    commands = np.asarray(commands, float)
    if commands.ndim != 2 or commands.shape[1] != scene.n_tendons:
        raise ValueError(f"commands must have shape (n, {scene.n_tendons}), got {commands.shape}")
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)):
        raise TypeError(f"chunk_size must be an integer, got {chunk_size!r}")
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    n = commands.shape[0]
    chunk = min(chunk_size, n)
    tally = _Tally()
    first = None
    start = time.perf_counter()
    with (
        BatchWriter(path, scene, n, attrs, chunk_rows=chunk, resume=resume) as writer,
        _interrupts() as check_interrupt,
    ):
        done = writer.rows_written
        if resume:
            _check_resumable(writer.file, commands, chunk)
            tally.add({name: writer.file[name][:done] for name in _TALLIED})
            for callback in (on_chunk, on_rows):
                if callback is not None and done:
                    callback(done)
        rest = commands[done:]
        parts = (
            pj.iter_batch(scene, rest, chunk_size=chunk, on_rows=on_rows, **solver_options)
            if len(rest)
            else ()
        )
        for part, eq in parts:
            rows = slice(part.start + done, part.stop + done)
            cols = chunk_columns(scene, commands[rows], eq)
            writer.write(rows, cols)
            tally.add(cols)
            tally.chunks += 1
            if first is None:
                first = time.perf_counter() - start
            if on_chunk is not None:
                on_chunk(rows.stop - rows.start)
            check_interrupt()
    wall = time.perf_counter() - start
    return BatchSummary(
        n=n,
        converged=tally.converged,
        stable=tally.stable,
        wall_s=wall,
        first_chunk_s=wall if first is None else first,
        chunks=tally.chunks,
        chunk_size=chunk,
        peak_memory_mib=peak_memory_mib(),
        max_residual_converged=tally.max_residual,
        peak_device_memory_mib=peak_device_memory_mib(),
        resumed_rows=done,
    )


_TALLIED = ("converged", "stable", "residual_norm")


@dataclasses.dataclass
class _Tally:
    """Running counts of a batch's rows for its summary."""

    converged: int = 0
    stable: int = 0
    max_residual: float = 0.0
    chunks: int = 0

    def add(self, columns: dict) -> None:
        ok = np.asarray(columns["converged"], bool)
        self.converged += int(ok.sum())
        self.stable += int((ok & np.asarray(columns["stable"], bool)).sum())
        if ok.any():
            self.max_residual = max(self.max_residual, float(columns["residual_norm"][ok].max()))


def _check_resumable(file, commands: np.ndarray, chunk: int) -> None:
    """The file was written for these commands in chunks of ``chunk`` rows."""
    done = int(file.attrs["rows_written"])
    if file["commands"].shape != commands.shape:
        raise ValueError(
            f"{file.filename} holds {file['commands'].shape[0]} rows of "
            f"{file['commands'].shape[1]} commands, not {commands.shape[0]} of {commands.shape[1]}"
        )
    stored = min(int(file.attrs.get("chunk_size", chunk)), commands.shape[0])
    if stored != chunk:  # other chunks would give other rounding in the rows still to solve
        raise ValueError(f"{file.filename} was written in chunks of {stored} rows, not {chunk}")
    if not np.array_equal(file["commands"][:done], commands[:done]):
        raise ValueError(f"{file.filename} was solved for other commands than these")


# ------------------------------------------------------------------------------ plot
def plot_workspace(path: str, png: str, max_points: int = 50_000, title: str | None = None):
    """Tip positions of a batch file in three views (x-y, x-z, y-z, mm), converged rows in blue
    and the others as red crosses (:func:`pacjax.plots.batch.plot_workspace`). At most
    ``max_points`` evenly strided rows are drawn."""
    import h5py

    from ..plots.batch import plot_workspace as draw

    with h5py.File(path, "r") as f:
        n = int(f.attrs["rows_written"])
        step = max(1, -(-n // max_points))
        tip = f["tip_position"][:n:step]
        ok = f["converged"][:n:step]
    draw(tip, ok, png, title=title, n_rows=n)
    return png
