"""Equilibria for batches of controls: vmapped, pooled, warm-started, sharded across devices.

Rows are solved in a pool of slots (``chunk_size``, at most :data:`CPU_POOL_SLOTS` per CPU
device): one compiled, ``vmap``-ed call runs the continuation of every slot for a few steps
(:func:`_steps_per_round`), and a slot whose row has finished is refilled with the next row
(its scaled starting point computed beforehand, a chunk of rows in one call). A
``vmap``-ed loop runs as many steps as its slowest row, so without the refill every chunk
would cost its slowest row's step count times its size; with it, a long batch costs about the
mean. Each row follows the iterates of
:func:`solve_equilibrium` (the same root finder, resumed round after round), so results agree
with single solves. The pool has a fixed size, so a batch of any length compiles once. On a
single CPU device two pools run side by side in threads (:func:`_lanes`), since one XLA:CPU
execution leaves part of the cores idle. With several devices (``jax.local_devices()``), the
pool is sharded along the batch axis with ``jax.sharding`` and XLA runs the shards in parallel.
In a multi-host run (``jax.distributed.initialize()``) each process passes the rows it owns
and shards them over its own devices; see docs/multihost.md.
"""

import dataclasses
import queue
import threading
from collections.abc import Callable, Iterator

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ._continuation import conservative_part, load_continuation, order_continuation, order_step
from ._equilibrium import (
    SolverOptions,
    _Scaled,
    as_traced_leaves,
    check_controls,
    check_start_contraction,
    equilibrium_from,
    make_solver,
    max_total_steps,
    solve_core,
    solver_dtype,
    start_point,
    static_load_sites,
)
from ._scene import Scene
from ._solution import Equilibrium

#: Continuation steps per round of the slot pool (a finished row waits at most this many
#: steps for its slot to be refilled): 2 on CPU, 4 on accelerators (see :func:`_steps_per_round`).
STEPS_PER_ROUND = {"cpu": 2}
_STEPS_PER_ROUND_DEFAULT = 4


def _steps_per_round() -> int:
    """Steps per round on the default backend. On XLA:CPU (the paper's robot with PAC, 1,000
    rows in a pool of 128 slots) 2 steps ran 1.95 s against 1.98-2.05 s for 3 and 2.10-2.29 s
    for 4: a finished slot idles for fewer steps, and a round costs little once the starting
    points are computed per block of rows (:func:`_start_block`) instead of in every round.
    """
    return STEPS_PER_ROUND.get(jax.default_backend(), _STEPS_PER_ROUND_DEFAULT)


_TAGS = frozenset()


@eqx.filter_jit
def _solve_chunk(scene, controls, q0, opts, params, update, conservative=False):
    def one(u, q, p):
        sc = scene if update is None else update(scene, p)
        if conservative:
            sc = conservative_part(sc)
        return solve_core(sc, u, q, opts)

    return jax.vmap(one)(controls, q0, params)


@eqx.filter_jit
def _start_block(scene, opts, update, controls, params, q0):
    """Scaled starting points (:func:`pacjax._equilibrium.start_point`) of a block of rows."""

    def one(u, p, q):
        sc = scene if update is None else update(scene, p)
        return start_point(_Scaled.build(sc, u), q, opts)

    return jax.vmap(one)(controls, params, q0)


@eqx.filter_jit
def _advance(scene, opts, update, controls, params, y, state, reset, y_reset, active):
    """One round of the slot pool: restart the ``reset`` slots from ``y_reset`` (scaled
    starting points from :func:`_start_block`, computed once per row rather than for every slot
    in every round), then run every active slot's continuation for up to
    :func:`_steps_per_round` steps (fewer when all are done).

    The steps are those of :func:`pacjax._equilibrium.solve_core` (the same root finder, resumed
    round after round), so a row's iterates do not depend on which rows share the pool.
    Returns the new ``(y, state)``, whether each slot is done, and its :class:`Equilibrium`.
    """
    dtype = controls.dtype
    limit = max_total_steps(opts)
    per_round = _steps_per_round()
    fn = _Scaled.root_fn

    def one(u, p, y_, st_, reset_, y_start, active_):
        sc = scene if update is None else update(scene, p)
        problem = _Scaled.build(sc, u)
        solver = make_solver(sc, opts, dtype)
        f_struct, aux_struct = jax.eval_shape(fn, y_, problem)
        st_start = solver.init(fn, y_start, problem, None, f_struct, aux_struct, _TAGS)
        y_ = jnp.where(reset_, y_start, y_)
        st_ = jtu.tree_map(lambda a, b: jnp.where(reset_, a, b), st_start, st_)

        def running(y, st):
            # As optimistix.root_find: stop when the solver terminates, y is not finite or
            # the step budget is spent.
            done, _ = solver.terminate(fn, y, problem, None, st, _TAGS)
            finite = jnp.all(jnp.isfinite(y))
            return active_ & ~done & finite & (st.step < limit)

        def cond(carry):
            y, st, k = carry
            return (k < per_round) & running(y, st)

        def body(carry):
            y, st, k = carry
            y, st, _ = solver.step(fn, y, problem, None, st, _TAGS)
            return y, st, k + 1

        y_, st_, _ = jax.lax.while_loop(cond, body, (y_, st_, jnp.asarray(0)))
        eq = equilibrium_from(sc, problem, solver, y_, st_, st_.step, opts.tol)
        return y_, st_, ~running(y_, st_), eq

    return jax.vmap(one)(controls, params, y, state, reset, y_reset, active)


#: Solver slots per CPU device. On XLA:CPU a row-step costs about the same in a pool of 128 as in
#: one of 1,000 (1.5 and 1.25 ms, the paper's robot with PAC), and a smaller pool is refilled
#: sooner, so 1,000 rows in a pool of 128 ran at 46 eq/s against 31 in one pool of 1,000.
CPU_POOL_SLOTS = 128


def _pool_slots(chunk: int, n_devices: int) -> int:
    """Slots of the solver pool: the chunk, capped per device on CPU (accelerators keep the
    whole chunk: their rows run in parallel); a multiple of the device count."""
    slots = chunk
    if jax.default_backend() == "cpu":
        slots = min(slots, CPU_POOL_SLOTS * n_devices)
    return -(-slots // n_devices) * n_devices


def _initial_state(scene, opts, size, dtype, sharding):
    """Placeholder ``(y, state)`` of a pool of ``size`` slots (every slot is reset first)."""
    n = scene.n_dofs
    solver = make_solver(scene, opts, dtype)
    y = jnp.zeros(n, dtype)
    f_struct = jax.ShapeDtypeStruct((n,), dtype)
    state = solver.init(None, y, None, None, f_struct, None, _TAGS)
    # Strongly typed, as _advance returns them (a weak type would compile a second version).
    y, state = jtu.tree_map(
        lambda x: jnp.asarray(jnp.broadcast_to(x, (size,) + x.shape), x.dtype), (y, state)
    )
    if sharding is not None:
        y, state = jax.device_put((y, state), sharding)
    return y, state


def _nearest_rows(done_controls: np.ndarray, controls: np.ndarray) -> np.ndarray:
    """Index of the nearest already-solved command for every row (squared Euclidean)."""
    d2 = (
        np.sum(controls**2, 1)[:, None]
        - 2.0 * controls @ done_controls.T
        + np.sum(done_controls**2, 1)[None, :]
    )
    return np.argmin(d2, axis=1)


def _sharding(n_devices: int):
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
    **options,
) -> Iterator[tuple[slice, Equilibrium]]:
    """Solve a batch chunk by chunk, yielding ``(rows, Equilibrium)`` as each chunk finishes.

    Memory stays bounded by the chunk size whatever the batch size: write each chunk out and
    drop it. Arguments as :func:`solve_batch`.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a pacjax.Scene, got {type(scene).__name__}")
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)):
        raise TypeError(f"chunk_size must be an integer, got {chunk_size!r}")
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    opts = SolverOptions(**options)
    dtype = solver_dtype(scene)
    scene = static_load_sites(as_traced_leaves(scene, dtype))
    try:
        controls_batch = np.asarray(controls_batch, dtype=float)
    except (TypeError, ValueError):
        raise TypeError("controls_batch must be an array of real numbers") from None
    if controls_batch.ndim != 2:
        raise ValueError(
            f"controls_batch must have shape (batch, {scene.n_tendons}), got {controls_batch.shape}"
        )
    check_controls(scene, controls_batch, dtype, batched=True)
    n = controls_batch.shape[0]
    if n == 0:
        raise ValueError("controls_batch is empty")
    if q0 is not None:
        q0 = np.asarray(q0, dtype=float)
        if q0.shape not in ((scene.n_dofs,), (n, scene.n_dofs)):
            raise ValueError(
                f"q0 must have shape ({scene.n_dofs},) or ({n}, {scene.n_dofs}), got {q0.shape}"
            )
        if not np.all(np.isfinite(q0)):
            raise ValueError("q0 contains NaN or infinite values")
        check_start_contraction(scene, q0.reshape(-1, scene.n_dofs))
        q0 = np.broadcast_to(q0, (n, scene.n_dofs))
    if params is not None:
        if update is None:
            raise ValueError("params= needs update=(scene, row_of_params) -> scene")
        params = jtu.tree_map(np.asarray, params)
        lengths = {x.shape[0] for x in jtu.tree_leaves(params)}
        if lengths != {n}:
            raise ValueError(f"every leaf of params needs a leading axis of {n}, got {lengths}")
    n_devices = len(jax.local_devices()) if devices is None else devices
    if not 1 <= n_devices <= len(jax.local_devices()):
        raise ValueError(f"devices must be in 1..{len(jax.local_devices())}, got {devices}")
    chunk = max(1, min(chunk_size, n))
    sharding = _sharding(n_devices)
    lanes = _lanes(chunk, sharding, warm_start)
    slots = _pool_slots(-(-chunk // lanes), n_devices)

    starts = _Starts(scene.n_dofs, q0, warm_start, chunk)
    pool = _pool_solve(
        scene, controls_batch, starts, params, update, opts, slots, chunk, dtype, sharding, lanes
    )
    buffers: dict[int, _ChunkBuffer] = {}
    next_chunk = 0
    for rows, q_start, eq_rows in pool:
        starts.record(controls_batch[rows], eq_rows)
        for c in (int(k) for k in np.unique(rows // chunk)):
            if c not in buffers:
                lo = c * chunk
                buffers[c] = _ChunkBuffer(slice(lo, min(lo + chunk, n)), eq_rows)
            mine = rows // chunk == c
            buffers[c].put(rows[mine], q_start[mine], eq_rows, mine)
        while next_chunk in buffers and buffers[next_chunk].full:
            part = buffers.pop(next_chunk)
            next_chunk += 1
            eq = jtu.tree_map(jnp.asarray, part.eq)
            retry = fallback or not scene.is_conservative
            if retry and opts.method == "ptc" and not np.all(part.eq.converged):
                u = controls_batch[part.rows]
                p = None if params is None else jtu.tree_map(lambda x, r=part.rows: x[r], params)
                eq = _retry_failed(scene, u, part.q_start, p, update, opts, eq, dtype, fallback)
            yield part.rows, eq


class _Starts:
    """Starting configurations: given, straight, or the equilibrium of the nearest command
    solved so far (a bounded pool of converged rows)."""

    def __init__(self, n_dofs, q0, warm_start, pool_size):
        self.n_dofs, self.q0, self.warm = n_dofs, q0, warm_start
        self.limit = 4 * pool_size
        self.done_u = np.zeros((0, 0))
        self.done_q = np.zeros((0, n_dofs))

    def __call__(self, rows, controls):
        if self.q0 is not None:
            return self.q0[rows]
        if self.warm and len(self.done_u):
            return self.done_q[_nearest_rows(self.done_u, controls)]
        return np.zeros((len(rows), self.n_dofs))

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


class _StartBlocks:
    """Starting points of the rows, computed a block of rows at a time (one compiled call per
    block, not one per slot and round): the unscaled ``q`` from ``starts`` and the scaled,
    aligned ``y`` the continuation starts from. Only the blocks still being handed out are kept.
    """

    def __init__(self, scene, controls, starts, params, update, opts, block, dtype, sharding):
        self.scene, self.controls, self.starts = scene, controls, starts
        self.params, self.update, self.opts = params, update, opts
        self.block, self.dtype, self.sharding = block, dtype, sharding
        n_devices = 1 if sharding is None else len(sharding.mesh.devices.flat)
        self.padded = -(-block // n_devices) * n_devices
        self.blocks: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def _compute(self, b):
        n = self.controls.shape[0]
        rows = np.arange(b * self.block, min((b + 1) * self.block, n))
        u = self.controls[rows]
        q = np.asarray(self.starts(rows, u), dtype=float)
        if self.params is None:
            p = np.zeros(len(rows))
        else:
            p = jtu.tree_map(lambda x: x[rows], self.params)
        inputs = (
            jnp.asarray(_pad(u, self.padded), self.dtype),
            jtu.tree_map(lambda x: jnp.asarray(_pad(x, self.padded)), p),
            jnp.asarray(_pad(q, self.padded), self.dtype),
        )
        if self.sharding is not None:
            inputs = jax.device_put(inputs, self.sharding)
        y = _start_block(self.scene, self.opts, self.update, *inputs)
        return q, np.asarray(y)[: len(rows)]

    def take(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(q, y)`` starts of ``rows`` (increasing), dropping the blocks handed out in full."""
        q_out = np.empty((len(rows), self.scene.n_dofs))
        y_out = np.empty((len(rows), self.scene.n_dofs))
        for b in np.unique(rows // self.block).tolist():
            if b not in self.blocks:
                self.blocks[b] = self._compute(b)
            mine = rows // self.block == b
            q, y = self.blocks[b]
            at = rows[mine] - b * self.block
            q_out[mine], y_out[mine] = q[at], y[at]
        last = rows[-1] if len(rows) else -1
        for b in [b for b in self.blocks if (b + 1) * self.block - 1 <= last]:
            del self.blocks[b]
        return q_out, y_out


#: Slot pools run side by side on a single CPU device, each in its own thread (see
#: :func:`_lanes`).
CPU_LANES = 2


def _lanes(chunk: int, sharding, warm_start: bool) -> int:
    """Slot pools to run at once, each with ``chunk / lanes`` slots (at most
    :data:`CPU_POOL_SLOTS`). One XLA:CPU execution of a round keeps about 1.45 of 2 cores busy
    (small kernels run on one thread, and the host works between rounds), so on a single CPU
    device :data:`CPU_LANES` pools share the rows, each in its own thread and with the same
    compiled round: the paper's robot with PAC, 1,000 rows, ran in 0.91-1.02 s on 2 cores
    (1.85-1.91 of them busy) against 1.11-1.22 s in one pool. Not with several devices (their
    shards already run in parallel) and not with warm starts (a row's start would depend on
    which rows the other pool had finished by then)."""
    if sharding is not None or warm_start or jax.default_backend() != "cpu":
        return 1
    return max(1, min(CPU_LANES, chunk))


class _RowQueue:
    """The rows in order, handed out with their starting points to the pools (thread-safe)."""

    def __init__(self, n: int, blocks: "_StartBlocks"):
        self.n, self.blocks, self.next = n, blocks, 0
        self.lock = threading.Lock()

    def take(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        with self.lock:
            rows = np.arange(self.next, min(self.next + k, self.n))
            self.next += len(rows)
            q, y = self.blocks.take(rows)
        return rows, q, y


_LANE_DONE = object()


def _pool_solve(
    scene, controls, starts, params, update, opts, size, block, dtype, sharding, lanes=1
):
    """Solve every row in ``lanes`` pools of ``size`` slots, refilled as rows finish (the
    batch does not wait for its slowest row); starting points are computed ``block`` rows at
    a time. Yields ``(rows, q_start, Equilibrium)`` of finished rows."""
    blocks = _StartBlocks(scene, controls, starts, params, update, opts, block, dtype, sharding)
    queue_ = _RowQueue(controls.shape[0], blocks)
    args = (scene, controls, queue_, params, update, opts, size, dtype, sharding)
    if lanes == 1:
        yield from _pool_lane(*args)
        return
    results: queue.SimpleQueue = queue.SimpleQueue()
    stop = threading.Event()
    # The first round compiles; the other pools wait for it rather than compile it again.
    compiled = threading.Event()

    def run(lane):
        try:
            if lane > 0:
                compiled.wait()
            for item in _pool_lane(*args, stop=stop, compiled=compiled if lane == 0 else None):
                results.put(item)
        except BaseException as error:  # handed to the caller's thread
            stop.set()
            results.put(error)
        finally:
            compiled.set()
            results.put(_LANE_DONE)

    threads = [threading.Thread(target=run, args=(k,), daemon=True) for k in range(lanes)]
    for t in threads:
        t.start()
    try:
        running = lanes
        while running:
            item = results.get()
            if item is _LANE_DONE:
                running -= 1
            elif isinstance(item, BaseException):
                raise item
            else:
                yield item
    finally:
        # Also when the caller stops early or a pool failed: the others stop after their round.
        stop.set()
        for t in threads:
            t.join()


def _pool_lane(
    scene,
    controls,
    rows_queue,
    params,
    update,
    opts,
    size,
    dtype,
    sharding,
    stop=None,
    compiled=None,
):
    """One pool of ``size`` slots taking rows from ``rows_queue`` until it is empty (or
    ``stop`` is set); ``compiled`` is set after its first round."""
    slot_row = np.full(size, -1)
    u_pool = np.zeros((size, controls.shape[1]))
    q_pool = np.zeros((size, scene.n_dofs))
    y_pool = np.zeros((size, scene.n_dofs))
    if params is None:
        p_pool = np.zeros((size,))
    else:
        p_pool = jtu.tree_map(lambda x: np.zeros((size,) + x.shape[1:], x.dtype), params)
    y, state = _initial_state(scene, opts, size, dtype, sharding)
    while stop is None or not stop.is_set():
        free = np.flatnonzero(slot_row < 0)
        rows, q_new, y_new = rows_queue.take(len(free))
        free = free[: len(rows)]
        reset = np.zeros(size, bool)
        reset[free] = True
        slot_row[free] = rows
        u_pool[free] = controls[rows]
        q_pool[free], y_pool[free] = q_new, y_new
        if params is not None:

            def assign(pool, x, free=free, rows=rows):
                pool[free] = x[rows]

            jtu.tree_map(assign, p_pool, params)
        active = slot_row >= 0
        if not active.any():
            return
        inputs = (
            jnp.asarray(u_pool, dtype),
            jtu.tree_map(jnp.asarray, p_pool),
            jnp.asarray(reset),
            jnp.asarray(y_pool, dtype),
            jnp.asarray(active),
        )
        if sharding is not None:
            inputs = jax.device_put(inputs, sharding)
        u_dev, p_dev, reset_dev, y_dev, active_dev = inputs
        y, state, done, eq = _advance(
            scene, opts, update, u_dev, p_dev, y, state, reset_dev, y_dev, active_dev
        )
        done = np.asarray(done) & active
        if compiled is not None:
            compiled.set()
        if done.any():
            slots = np.flatnonzero(done)
            eq_rows = jtu.tree_map(lambda x, s=slots: np.asarray(x)[s], eq)
            yield slot_row[slots], q_pool[slots].copy(), eq_rows
            slot_row[slots] = -1


def _pad(x, size):
    if x is None or x.shape[0] == size:
        return x
    pad = np.repeat(x[-1:], size - x.shape[0], axis=0)
    return np.concatenate([x, pad])


def _run_chunk(scene, u, q, p, update, opts, chunk, dtype, sharding, conservative=False):
    m = u.shape[0]
    u_pad = jnp.asarray(_pad(u, chunk), dtype)
    q_pad = jnp.asarray(_pad(q, chunk), dtype)
    p_pad = None if p is None else jtu.tree_map(lambda x: jnp.asarray(_pad(x, chunk)), p)
    if sharding is not None:
        u_pad, q_pad = jax.device_put((u_pad, q_pad), sharding)
        if p_pad is not None:
            p_pad = jax.device_put(p_pad, sharding)
    if p_pad is None:
        p_pad = jnp.zeros((chunk,), dtype)
    eq = _solve_chunk(scene, u_pad, q_pad, opts, p_pad, update, conservative)
    return jtu.tree_map(lambda x: x[:m], eq)


def _retry_failed(scene, u, q, p, update, opts, eq, dtype, flow=True):
    """Re-solve the rows that failed, keeping whichever converged: for a non-conservative scene
    first by load continuation (from the equilibrium of its conservative part, see
    :func:`pacjax._continuation.conservative_part`), for ``PolynomialCurvature`` of order >= 2
    by order continuation (from the equilibrium one order lower, itself retried the same way,
    see :func:`pacjax._continuation.order_step`), then, with ``flow``, with the diffrax flow."""

    def rows_of(x, rows):
        return None if x is None else jtu.tree_map(lambda a: a[rows], x)

    def solve_rows(rows, starts, options, conservative=False, sc=scene):
        # Padded to a power of two: a batch with a varying number of failures compiles the
        # retry a few times, not once per count.
        size = 1 << (len(rows) - 1).bit_length()
        return _run_chunk(
            sc, u[rows], starts, rows_of(p, rows), update, options, size, dtype, None, conservative
        )

    def merge(eq, rows, retry):
        better = np.asarray(retry.converged)
        if not better.any():
            return eq
        return jtu.tree_map(lambda a, b: a.at[rows[better]].set(b[better]), eq, retry)

    if np.all(np.asarray(eq.converged)):
        return eq
    if not scene.is_conservative:
        bad = np.flatnonzero(~np.asarray(eq.converged))
        retry = load_continuation(lambda cons, start: solve_rows(bad, start, opts, cons), q[bad])
        eq = merge(eq, bad, retry)
    step = order_step(scene)
    bad = np.flatnonzero(~np.asarray(eq.converged))
    if step is not None and bad.size:

        def solve_low(start):
            low = solve_rows(bad, start, opts, sc=step.scene)
            return _retry_failed(
                step.scene, u[bad], start, rows_of(p, bad), update, opts, low, dtype, flow=False
            )

        retry = order_continuation(step, solve_low, lambda s: solve_rows(bad, s, opts), q[bad])
        eq = merge(eq, bad, retry)
    bad = np.flatnonzero(~np.asarray(eq.converged))
    if flow and bad.size:
        eq = merge(eq, bad, solve_rows(bad, q[bad], dataclasses.replace(opts, method="flow")))
    return eq


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
    **options,
) -> Equilibrium:
    """Equilibria for a batch of controls; an :class:`Equilibrium` with a leading batch axis.

    Args:
        scene: the :class:`Scene`.
        controls_batch: (batch, n_tendons) controls.
        q0: starting configuration(s), (n_dofs,) or (batch, n_dofs); default straight.
        params: optional pytree of per-row values (leading axis ``batch``), e.g. payload masses,
            applied to the scene by ``update(scene, row) -> scene`` (use ``eqx.tree_at``).
        chunk_size: rows per output chunk, and slots of the solver pool (rows solved at once;
            on CPU at most :data:`CPU_POOL_SLOTS` per device, and on a single CPU device split
            into two pools that run side by side); memory is bounded by it.
        warm_start: start each row from the equilibrium of the nearest command solved so far
            (the first ``chunk_size`` rows start straight; helps on grids and paths).
        devices: number of devices to shard each chunk over (default all).
        progress: show a progress bar (default: when there is more than one chunk).
        fallback: re-solve rows that failed with the diffrax flow. Failed rows of a
            non-conservative scene are first re-solved by load continuation whatever it says.
        **options: :class:`SolverOptions` fields.
    """
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
        **options,
    )
    n = np.shape(controls_batch)[0] if np.ndim(controls_batch) == 2 else 0
    show = progress if progress is not None else n > chunk_size
    if show:
        from tqdm.auto import tqdm

        bar = tqdm(total=n, unit="eq", desc="equilibria")
    results = []
    for rows, eq in parts:
        results.append(jtu.tree_map(np.asarray, eq))
        if show:
            bar.update(rows.stop - rows.start)
    if show:
        bar.close()
    return jtu.tree_map(lambda *xs: jnp.asarray(np.concatenate(xs)), *results)
