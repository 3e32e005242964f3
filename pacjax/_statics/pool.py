"""The slot pool of :func:`pacjax.solve_batch`: rows solved a few continuation steps at a time,
each slot refilled as soon as its row has finished.

One compiled, ``vmap``-ed call (:func:`_advance`) runs the continuation of every slot for
:func:`_steps_per_round` steps; the starting points come a block of rows at a time
(:class:`_StartBlocks`). On a single CPU device two pools take rows from one queue, each in its
own thread (:func:`pool_lanes`); with several devices the pool is sharded along the slots.
"""

import collections
import functools
import queue
import threading

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._jit import jit
from .equilibrium import equilibrium_from, make_solver, max_total_steps, start_point
from .problem import ScaledProblem

#: Continuation steps per round of the slot pool (a finished row waits at most this many
#: steps for its slot to be refilled; see :func:`_steps_per_round`).
STEPS_PER_ROUND = 8
#: The same while rows wait in the queue for a slot, per backend (see :func:`_steps_per_round`).
QUEUED_STEPS_PER_ROUND = {"cpu": 6}


def _steps_per_round(rows_waiting: bool = False) -> int:
    """Steps per round on the default backend. Fewer steps per round leave a finished slot
    idle for fewer steps; more pay the host's work between rounds (dispatch, refilling the
    slots, and each slot's restart state and result, computed for every slot in every round)
    less often, which decides small pools (a fit's batches of 16 frames) and accelerators. On
    XLA:CPU 8 was as fast as 2 on 2,000 rows in a pool of 128 and faster on small pools; while
    rows wait for a slot, a finished row's idle steps cost a waiting row's progress, and rounds
    of 6 are faster there. On a GPU rounds of 8 beat rounds of 4 on every batch measured
    (``benchmarks/RESULTS.md``, "Figures behind the solver's settings", "A first step as long
    as Newton's" and "The side by side on a GPU").
    """
    backend = jax.default_backend()
    if rows_waiting and backend in QUEUED_STEPS_PER_ROUND:
        return QUEUED_STEPS_PER_ROUND[backend]
    return STEPS_PER_ROUND


_TAGS = frozenset()


@jit
def _start_block(scene, opts, update, controls, params, q0):
    """Scaled starting points (:func:`pacjax._statics.equilibrium.start_point`) of a block of
    rows."""

    def one(u, p, q):
        sc = scene if update is None else update(scene, p)
        return start_point(ScaledProblem.build(sc, u), q, opts)

    return jax.vmap(one)(controls, params, q0)


@jit
def _advance(scene, opts, update, controls, params, y, state, reset, y_reset, active, per_round):
    """One round of the slot pool: restart the ``reset`` slots from ``y_reset`` (scaled
    starting points from :func:`_start_block`, computed once per row rather than for every slot
    in every round), then run every active slot's continuation for up to ``per_round`` steps
    (fewer when all are done; an array, so that rounds of either length share one program).

    The steps are those of :func:`pacjax._statics.equilibrium.solve_core` (the same root finder,
    resumed round after round), so a row's iterates do not depend on which rows share the pool.
    Returns the new ``(y, state)``, whether each slot is done, and its :class:`Equilibrium`.
    """
    dtype = controls.dtype
    limit = max_total_steps(opts)
    fn = ScaledProblem.root_fn

    def one(u, p, y_, st_, reset_, y_start, active_):
        sc = scene if update is None else update(scene, p)
        problem = ScaledProblem.build(sc, u)
        solver = make_solver(sc, opts, dtype)
        # (eqx.filter_eval_shape keeps the static load sites Python numbers, as root_find does)
        f_struct, aux_struct = eqx.filter_eval_shape(fn, y_, problem)
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
#: a much larger one, and a smaller pool is refilled sooner (``benchmarks/RESULTS.md``,
#: "Figures behind the solver's settings").
CPU_POOL_SLOTS = 128


def pool_slots(chunk: int, n_devices: int) -> int:
    """Slots of the solver pool: the chunk, capped per device on CPU (accelerators keep the
    whole chunk: their rows run in parallel); a multiple of the device count."""
    slots = chunk
    if jax.default_backend() == "cpu":
        slots = min(slots, CPU_POOL_SLOTS * n_devices)
    return -(-slots // n_devices) * n_devices


def _initial_state(scene, opts, size, dtype, sharding):
    """Placeholder ``(y, state)`` of a pool of ``size`` slots: zeros of the solver state's
    shapes. Their values are never read: a slot runs only after :func:`_advance` has reset it
    to a row's start, and an idle slot's outputs are dropped."""
    solver = make_solver(scene, opts, dtype)
    return _placeholder(solver, scene.n_dofs, np.dtype(dtype), size, sharding)


@functools.lru_cache(maxsize=16)
def _placeholder(solver, n: int, dtype, size: int, sharding):
    # Made from shapes alone, once per solver, size and sharding: ``solver.init`` run op by op
    # compiled a dozen small programs in every new process and cost more than the rounds of a
    # small batch (the arrays are immutable, so pools can share them).
    f_struct = jax.ShapeDtypeStruct((n,), dtype)
    shapes = jax.eval_shape(
        lambda y: (y, solver.init(None, y, None, None, f_struct, None, _TAGS)), f_struct
    )
    # Strongly typed, as _advance returns them (a weak type would compile a second version).
    zeros = jtu.tree_map(lambda x: np.zeros((size,) + x.shape, x.dtype), shapes)
    return jax.device_put(zeros, sharding)


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
            jnp.asarray(pad_rows(u, self.padded), self.dtype),
            jtu.tree_map(lambda x: jnp.asarray(pad_rows(x, self.padded)), p),
            jnp.asarray(pad_rows(q, self.padded), self.dtype),
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
#: :func:`pool_lanes`).
CPU_LANES = 2


def pool_lanes(chunk: int, sharding, warm_start: bool) -> int:
    """Slot pools to run at once, each with ``chunk / lanes`` slots (at most
    :data:`CPU_POOL_SLOTS`). One XLA:CPU execution of a round keeps about 1.45 of 2 cores busy
    (small kernels run on one thread, and the host works between rounds), so on a single CPU
    device :data:`CPU_LANES` pools share the rows, each in its own thread and with the same
    compiled round, which keeps the cores busy between one pool's rounds (the figures are in
    ``benchmarks/RESULTS.md``, "Figures behind the solver's settings"). Not with several
    devices (their shards already run in parallel) and not with warm starts (a row's start
    would depend on which rows the other pool had finished by then)."""
    if sharding is not None or warm_start or jax.default_backend() != "cpu":
        return 1
    return max(1, min(CPU_LANES, chunk))


class _RowQueue:
    """The rows in order, handed out with their starting points to the pools (thread-safe)."""

    def __init__(self, n: int, blocks: "_StartBlocks"):
        self.n, self.blocks, self.next = n, blocks, 0
        self.lock = threading.Lock()

    def waiting(self) -> bool:
        """Whether rows are left to hand out."""
        with self.lock:
            return self.next < self.n

    def take(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        with self.lock:
            rows = np.arange(self.next, min(self.next + k, self.n))
            self.next += len(rows)
            q, y = self.blocks.take(rows)
        return rows, q, y


_LANE_DONE = object()


def pool_solve(
    scene, controls, starts, params, update, opts, size, block, dtype, sharding, lanes=1
):
    """Solve every row in ``lanes`` pools of ``size`` slots, refilled as rows finish (the
    batch does not wait for its slowest row); starting points are computed ``block`` rows at
    a time. Yields ``(rows, q_start, Equilibrium)`` of finished rows."""
    blocks = _StartBlocks(scene, controls, starts, params, update, opts, block, dtype, sharding)
    queue_ = _RowQueue(controls.shape[0], blocks)
    ready = _RoundCompile(scene, controls, params, update, opts, size, dtype, sharding)
    ready.start()
    args = (scene, controls, queue_, params, update, opts, size, dtype, sharding)
    if lanes == 1:
        try:
            yield from _pool_lane(*args, ready=ready)
        finally:
            ready.join()
        return
    results: queue.SimpleQueue = queue.SimpleQueue()
    stop = threading.Event()

    def run():
        try:
            for item in _pool_lane(*args, stop=stop, ready=ready):
                results.put(item)
        except BaseException as error:  # handed to the caller's thread
            stop.set()
            results.put(error)
        finally:
            results.put(_LANE_DONE)

    threads = [threading.Thread(target=run, daemon=True) for _ in range(lanes)]
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
        ready.join()


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
    ready=None,
):
    """One pool of ``size`` slots taking rows from ``rows_queue`` until it is empty (or
    ``stop`` is set); its rounds wait for ``ready`` (the round compiled, see
    :class:`_RoundCompile`)."""
    slot_row = np.full(size, -1)
    u_pool, p_pool, y_pool = _empty_pool(scene, controls, params, size)
    q_pool = np.zeros((size, scene.n_dofs))
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
        if ready is not None:
            ready.wait()
        pool = (u_pool, p_pool, y, state, reset, y_pool, active)
        waiting = rows_queue.waiting()
        y, state, done, eq = _round(scene, opts, update, dtype, sharding, *pool, waiting)
        done = np.asarray(done) & active
        if done.any():
            slots = np.flatnonzero(done)
            eq_rows = jtu.tree_map(lambda x, s=slots: np.asarray(x)[s], eq)
            yield slot_row[slots], q_pool[slots].copy(), eq_rows
            slot_row[slots] = -1


def _empty_pool(scene, controls, params, size):
    """Host buffers of a pool's commands, parameters and scaled starting points."""
    u_pool = np.zeros((size, controls.shape[1]))
    y_pool = np.zeros((size, scene.n_dofs))
    if params is None:
        p_pool = np.zeros((size,))
    else:
        p_pool = jtu.tree_map(lambda x: np.zeros((size,) + x.shape[1:], x.dtype), params)
    return u_pool, p_pool, y_pool


def _round(
    scene, opts, update, dtype, sharding, u_pool, p_pool, y, state, reset, y_pool, active, waiting
):
    """One :func:`_advance` round from the pool's host buffers; ``waiting``: whether rows wait
    in the queue for a slot (:func:`_steps_per_round`)."""
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
    per_round = jnp.asarray(_steps_per_round(waiting), jnp.int32)
    return _advance(
        scene, opts, update, u_dev, p_dev, y, state, reset_dev, y_dev, active_dev, per_round
    )


#: Rounds already run in this process (:func:`_round_key`), most recent last: a pool of the
#: same kind needs no idle round to compile it.
_ROUNDS_RUN: collections.OrderedDict = collections.OrderedDict()
_ROUNDS_RUN_MAX = 256
# Pools of several threads (the lanes, and the user's) look keys up and add them.
_ROUNDS_LOCK = threading.Lock()


def _round_has_run(key) -> bool:
    with _ROUNDS_LOCK:
        if key is None or key not in _ROUNDS_RUN:
            return False
        _ROUNDS_RUN.move_to_end(key)
        return True


def _round_ran(key) -> None:
    if key is None:
        return
    with _ROUNDS_LOCK:
        _ROUNDS_RUN[key] = None
        while len(_ROUNDS_RUN) > _ROUNDS_RUN_MAX:
            _ROUNDS_RUN.popitem(last=False)


def _leaf_key(x):
    if hasattr(x, "shape") and hasattr(x, "dtype"):
        return tuple(x.shape), str(x.dtype), bool(getattr(x, "weak_type", False))
    return x


def _round_key(scene, controls, params, update, opts, size, dtype, sharding):
    """What decides the compiled round of a pool: the scene's and options' structure, static
    values and array shapes, the parameters' per-row shapes, the update function, the pool's
    size, dtype and sharding. None where some part cannot be hashed."""
    leaves, tree = jtu.tree_flatten((scene, opts))
    p_leaves, p_tree = jtu.tree_flatten(params)
    key = (
        tree,
        tuple(_leaf_key(x) for x in leaves),
        p_tree,
        tuple((np.shape(x)[1:], np.asarray(x).dtype.str) for x in p_leaves),
        update,
        controls.shape[1:],
        size,
        np.dtype(dtype).str,
        sharding,
    )
    try:
        hash(key)
    except TypeError:
        return None
    return key


class _RoundCompile(threading.Thread):
    """Compiles the pool's round in the background (a round with no slot active), while the
    first block of starting points is traced, compiled and computed: the two compilations
    overlap. The pools wait for it (:meth:`wait`), which raises what it raised. A round of the
    same kind already run in this process is compiled: then the idle round is not run (what it
    cost a warm batch of a few rows is in ``benchmarks/RESULTS.md``, "Chord ends by index")."""

    def __init__(self, scene, controls, params, update, opts, size, dtype, sharding):
        super().__init__(daemon=True)
        self.args = (scene, controls, params, update, opts, size, dtype, sharding)
        self.error = None

    def run(self):
        scene, controls, params, update, opts, size, dtype, sharding = self.args
        try:
            key = _round_key(*self.args)
            if _round_has_run(key):
                return
            u_pool, p_pool, y_pool = _empty_pool(scene, controls, params, size)
            y, state = _initial_state(scene, opts, size, dtype, sharding)
            idle = np.zeros(size, bool)
            pool = (u_pool, p_pool, y, state, idle, y_pool, idle)
            out = _round(scene, opts, update, dtype, sharding, *pool, False)
            jax.block_until_ready(out)
            _round_ran(key)
        except BaseException as error:  # raised again in the pools' threads
            self.error = error

    def wait(self):
        self.join()
        if self.error is not None:
            raise self.error


def pad_rows(x, size):
    if x is None or x.shape[0] == size:
        return x
    pad = np.repeat(x[-1:], size - x.shape[0], axis=0)
    return np.concatenate([x, pad])
