"""Equilibria for batches of controls: vmapped, pooled, warm-started, sharded across devices.

Rows are solved in a pool of slots (:mod:`pacjax._statics.pool`; ``chunk_size``, at most
``CPU_POOL_SLOTS`` per CPU device): one compiled, ``vmap``-ed loop steps the continuation of
every slot, and a slot whose row has finished takes the next row on the device, at the next
step (its scaled starting point computed beforehand, a block of rows in one call). A
``vmap``-ed loop runs as many steps as its slowest row, so without the refill every chunk would
cost its slowest row's step count times its size; with it, a long batch costs about the mean.
Each row follows the iterates of :func:`solve_equilibrium` (the same root finder, resumed call
after call), so results agree with single solves within the tolerance: the pool's root finder
also tries each next step ahead with one residual evaluation and ends a row where that step
lands within the tolerance, one linearisation sooner than a single solve, which keeps a
linearisation at its result for its derivatives (a batch takes none). The pool has a fixed
size, so a batch of any length compiles once. On a single CPU device two pools run side by side
in threads, since one XLA:CPU execution leaves part of the cores idle. With several devices
(``jax.local_devices()``), the pool is sharded along the batch axis with ``jax.sharding`` and
XLA runs the shards in parallel. In a multi-host run (``jax.distributed.initialize()``) each
process passes the rows it owns and shards them over its own devices; see docs/multihost.md.
"""

from collections.abc import Callable, Iterator

import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .._jit import jit
from .._model.inputs import (
    as_traced_leaves,
    check_controls,
    check_q,
    check_scene,
    solver_dtype,
    static_load_sites,
)
from .._model.scene import Scene
from .continuation import conservative_part, retry_failed
from .equilibrium import solve_core
from .options import SolverOptions, resolve_options
from .pool import pad_rows, pool_lanes, pool_slots, pool_solve
from .ringcheck import check_rows
from .solution import Equilibrium


@jit
def _solve_chunk(scene, controls, q0, opts, params, update, conservative=False):
    def one(u, q, p):
        sc = scene if update is None else update(scene, p)
        if conservative:
            sc = conservative_part(sc)
        return solve_core(sc, u, q, opts)

    return jax.vmap(one)(controls, q0, params)


def _nearest_rows(done_controls: np.ndarray, controls: np.ndarray) -> np.ndarray:
    """Index of the nearest already-solved command for every row (squared Euclidean)."""
    d2 = (
        np.sum(controls**2, 1)[:, None]
        - 2.0 * controls @ done_controls.T
        + np.sum(done_controls**2, 1)[None, :]
    )
    return np.argmin(d2, axis=1)


def row_sharding(n_devices: int) -> NamedSharding | None:
    """Rows (the leading axis) split over the first ``n_devices`` local devices; None for one."""
    if n_devices <= 1:
        return None
    mesh = Mesh(np.asarray(jax.local_devices()[:n_devices]), ("batch",))
    return NamedSharding(mesh, PartitionSpec("batch"))


def iter_batch(
    scene: Scene,
    controls_batch,
    q0=None,
    *,
    params=None,
    update: Callable | None = None,
    chunk_size: int = 1024,
    warm_start: bool = False,
    devices: int | None = None,
    fallback: bool = True,
    options: SolverOptions | None = None,
    on_rows: Callable[[int], None] | None = None,
    **overrides,
) -> Iterator[tuple[slice, Equilibrium]]:
    """Solve a batch chunk by chunk, yielding ``(rows, Equilibrium)`` as each chunk finishes.

    Memory stays bounded by the chunk size whatever the batch size: write each chunk out and
    drop it. Arguments as :func:`solve_batch`; ``on_rows(count)``, if given, is called as rows
    leave the solver's slot pool (which finishes rows in any order, several times per chunk):
    for a progress display that moves row by row.
    """
    check_scene(scene)
    _check_not_traced(scene, controls_batch, q0, params)
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)):
        raise TypeError(f"chunk_size must be an integer, got {chunk_size!r}")
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    dtype = solver_dtype(scene)
    opts = resolve_options(options, dtype, **overrides)
    scene = static_load_sites(as_traced_leaves(scene, dtype))
    controls_batch = np.asarray(check_controls(scene, controls_batch, dtype, batched=True))
    n = controls_batch.shape[0]
    if n == 0:
        raise ValueError("controls_batch is empty")
    q0 = check_q(scene, q0, dtype, rows=n)
    params = _check_params(params, update, n)
    n_devices = check_devices(devices)
    chunk = max(1, min(chunk_size, n))
    sharding = row_sharding(n_devices)
    lanes = pool_lanes(chunk, sharding, warm_start)
    slots = pool_slots(-(-chunk // lanes), n_devices)

    starts = _Starts(np.asarray(scene.rest_configuration(dtype)), q0, warm_start, chunk)
    # Starting points a pool's worth at a time: the first pool starts after one such block
    # (a block of the whole chunk held both lanes for about a tenth of a 1,000-row batch), and
    # each later block is computed while the other lane runs its steps. Warm starts keep
    # blocks of the chunk: a row's start is the nearest row solved before its block.
    block = chunk if warm_start else slots
    pool = pool_solve(
        scene, controls_batch, starts, params, update, opts, slots, block, dtype, sharding, lanes
    )
    retry = (fallback or not scene.is_conservative) and opts.method == "ptc"
    for part in _chunks_in_order(pool, starts, controls_batch, chunk, on_rows):
        eq = jtu.tree_map(jnp.asarray, part.eq)
        if retry and not np.all(part.eq.converged):
            u = controls_batch[part.rows]
            p = None if params is None else jtu.tree_map(lambda x, r=part.rows: x[r], params)
            eq = _retry_failed(scene, u, part.q_start, p, update, opts, eq, dtype, fallback)
        check_rows(scene, eq.q)
        yield part.rows, eq


def _check_not_traced(*trees) -> None:
    """The batch solver runs its pool from Python, chunk by chunk: it cannot be traced."""
    leaves = jtu.tree_leaves(trees)
    if any(isinstance(x, jax.core.Tracer) for x in leaves):
        raise TypeError(
            "solve_batch/iter_batch cannot be traced (jax.jit, jax.grad, jax.vmap): they run "
            "their solver pool from Python; for a traced or differentiated batch use "
            "jax.vmap(pj.solve_equilibrium)"
        )


def _check_params(params, update, n: int):
    """Per-row parameters as numpy, each leaf with a leading axis of ``n`` rows."""
    if params is None:
        return None
    if update is None:
        raise ValueError("params= needs update=(scene, row_of_params) -> scene")
    params = jtu.tree_map(np.asarray, params)
    lengths = {x.shape[0] for x in jtu.tree_leaves(params)}
    if lengths != {n}:
        raise ValueError(f"every leaf of params needs a leading axis of {n}, got {lengths}")
    return params


def check_devices(devices: int | None) -> int:
    """How many local devices to shard over (default all)."""
    n_devices = len(jax.local_devices()) if devices is None else devices
    if not 1 <= n_devices <= len(jax.local_devices()):
        raise ValueError(f"devices must be in 1..{len(jax.local_devices())}, got {devices}")
    return n_devices


def _chunks_in_order(
    pool, starts, controls_batch, chunk: int, on_rows=None
) -> Iterator["_ChunkBuffer"]:
    """The output chunks, in order, each as soon as all its rows have come out of the pool
    (which finishes rows in any order); warm starts learn from every finished row."""
    n = controls_batch.shape[0]
    buffers: dict[int, _ChunkBuffer] = {}
    next_chunk = 0
    for rows, q_start, eq_rows in pool:
        starts.record(controls_batch[rows], eq_rows)
        if on_rows is not None:
            on_rows(len(rows))
        for c in (int(k) for k in np.unique(rows // chunk)):
            if c not in buffers:
                lo = c * chunk
                buffers[c] = _ChunkBuffer(slice(lo, min(lo + chunk, n)), eq_rows)
            mine = rows // chunk == c
            buffers[c].put(rows[mine], q_start[mine], eq_rows, mine)
        while next_chunk in buffers and buffers[next_chunk].full:
            yield buffers.pop(next_chunk)
            next_chunk += 1


class _Starts:
    """Starting configurations: given, the rest configuration, or the equilibrium of the
    nearest command solved so far (a bounded pool of converged rows)."""

    def __init__(self, rest, q0, warm_start, pool_size):
        self.rest, self.q0, self.warm = rest, q0, warm_start
        self.limit = 4 * pool_size
        self.done_u = np.zeros((0, 0))
        self.done_q = np.zeros((0, len(rest)))

    def __call__(self, rows, controls):
        if self.q0 is not None:
            return self.q0[rows]
        if self.warm and len(self.done_u):
            return self.done_q[_nearest_rows(self.done_u, controls)]
        return np.broadcast_to(self.rest, (len(rows), len(self.rest))).copy()

    def record(self, controls, eq_rows):
        if not self.warm:
            return
        ok = np.asarray(eq_rows.converged)
        u = controls[ok]
        q = np.asarray(eq_rows.q)[ok]
        if len(self.done_u):
            u, q = np.concatenate([self.done_u, u]), np.concatenate([self.done_q, q])
        self.done_u, self.done_q = u[-self.limit :], q[-self.limit :]


class _ChunkBuffer:
    """Results of the rows of one output chunk, filled as their slots finish."""

    def __init__(self, rows: slice, like: Equilibrium):
        self.rows = rows
        m = rows.stop - rows.start
        self.eq = jtu.tree_map(lambda x: np.empty((m,) + x.shape[1:], x.dtype), like)
        self.q_start = np.empty((m,) + like.q.shape[1:])
        self.missing = m

    def put(self, rows, q_start, eq_rows, mine):
        at = rows - self.rows.start

        def fill(buf, x):
            buf[at] = x[mine]

        jtu.tree_map(fill, self.eq, eq_rows)
        self.q_start[at] = q_start
        self.missing -= len(rows)

    @property
    def full(self) -> bool:
        return self.missing == 0


def _run_chunk(scene, u, q, p, update, opts, chunk, dtype, sharding, conservative=False):
    m = u.shape[0]
    u_pad = jnp.asarray(pad_rows(u, chunk), dtype)
    q_pad = jnp.asarray(pad_rows(q, chunk), dtype)
    p_pad = None if p is None else jtu.tree_map(lambda x: jnp.asarray(pad_rows(x, chunk)), p)
    if sharding is not None:
        u_pad, q_pad = jax.device_put((u_pad, q_pad), sharding)
        if p_pad is not None:
            p_pad = jax.device_put(p_pad, sharding)
    if p_pad is None:
        p_pad = jnp.zeros((chunk,), dtype)
    eq = _solve_chunk(scene, u_pad, q_pad, opts, p_pad, update, conservative)
    return jtu.tree_map(lambda x: x[:m], eq)


def _retry_failed(scene, u, q, p, update, opts, eq, dtype, flow=True):
    """The failed rows of a chunk (controls ``u``, starts ``q``, row parameters ``p``) solved
    again by :func:`pacjax._statics.continuation.retry_failed`."""

    def solve_rows(rows, starts, options, conservative=False, scene=scene):
        # Padded to a power of two: a batch with a varying number of failures compiles the
        # retry a few times, not once per count.
        size = 1 << (len(rows) - 1).bit_length()
        p_rows = None if p is None else jtu.tree_map(lambda a: a[rows], p)
        return _run_chunk(
            scene, u[rows], starts, p_rows, update, options, size, dtype, None, conservative
        )

    return retry_failed(scene, eq, q, solve_rows, opts, flow)


def solve_batch(
    scene: Scene,
    controls_batch,
    q0=None,
    *,
    params=None,
    update: Callable | None = None,
    chunk_size: int = 1024,
    warm_start: bool = False,
    devices: int | None = None,
    progress: bool | None = None,
    fallback: bool = True,
    options: SolverOptions | None = None,
    **overrides,
) -> Equilibrium:
    """Equilibria for a batch of controls; an :class:`Equilibrium` with a leading batch axis.

    Args:
        scene: the :class:`Scene`.
        controls_batch: (batch, n_tendons) controls.
        q0: starting configuration(s), (n_dofs,) or (batch, n_dofs); default the rest
            configuration (straight unless a segment has a rest curvature).
        params: optional pytree of per-row values (leading axis ``batch``), e.g. payload masses,
            applied to the scene by ``update(scene, row) -> scene`` (use ``eqx.tree_at``).
        chunk_size: rows per output chunk, and slots of the solver pool (rows solved at once;
            on CPU at most ``pacjax._statics.pool.CPU_POOL_SLOTS`` per device, and on a single CPU
            device split into two pools that run side by side); memory is bounded by it.
        warm_start: start each row from the equilibrium of the nearest command solved so far
            (the first ``chunk_size`` rows start straight; helps on grids and paths).
        devices: number of devices to shard each chunk over (default all).
        progress: show a progress bar (default: when there is more than one chunk).
        fallback: re-solve rows that failed with the diffrax flow. Failed rows of a
            non-conservative scene are first re-solved by load continuation whatever it says.
        options: :class:`SolverOptions` (default ``SolverOptions()``).
        **overrides: single :class:`SolverOptions` fields replaced in ``options`` (``tol``,
            ``max_steps``, ...); an unknown name raises a TypeError.
    """
    n = np.shape(controls_batch)[0] if np.ndim(controls_batch) == 2 else 0
    bar = None
    if progress if progress is not None else n > chunk_size:
        from tqdm.auto import tqdm

        bar = tqdm(total=n, unit="eq", desc="equilibria")
    parts = iter_batch(
        scene,
        controls_batch,
        q0,
        params=params,
        update=update,
        chunk_size=chunk_size,
        warm_start=warm_start,
        devices=devices,
        fallback=fallback,
        options=options,
        on_rows=None if bar is None else bar.update,
        **overrides,
    )
    try:
        results = [jtu.tree_map(np.asarray, eq) for _, eq in parts]
    finally:
        if bar is not None:
            bar.close()
    return jtu.tree_map(lambda *xs: jnp.asarray(np.concatenate(xs)), *results)
