"""The slot pool of :func:`pacjax.solve_batch`: rows solved side by side in a fixed number of
slots, each slot refilled as soon as its row has finished.

One compiled, ``vmap``-ed call (:func:`_advance`) steps every slot's continuation and, on the
device, hands each slot that finishes the next pending row; the host collects the finished
rows and hands over more between calls. The starting points come a block of rows at a time
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

#: Steps one call of the pool (:func:`_advance`) runs at most: a call ends sooner, once a slot
#: is free and no row is pending for it, or once every slot is done. The cap bounds how long
#: finished rows wait to be reported while slow rows run on.
MAX_STEPS_PER_CALL = 64

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
def _advance(scene, opts, update, slots, pending, n_pending, drain, max_steps):
    """Steps of the slot pool, each slot refilled on the device as soon as its row is done.

    ``slots = (u, p, y, state, row)``: every slot's commands, parameters, scaled iterate and
    solver state, and whether it holds a row (``row >= 0``; -1: free); ``pending =
    (u, p, y)``: the next ``n_pending`` rows (local indices ``size + k``) and their scaled
    starting points (from :func:`_start_block`). Each step advances every running slot by one
    continuation step, then hands the pending rows, in order, to the slots that are free. The
    call returns once every slot is done if ``drain`` (no more rows will come), else as soon as
    a slot is free and no pending row is left for it (the host then hands over more), and after
    ``max_steps`` steps at most. So no slot waits for a row while rows are pending, and the
    host's work between calls is paid once per pool's worth of rows.

    The steps are those of :func:`pacjax._statics.equilibrium.solve_core` (the same root finder,
    resumed call after call, with each next step tried ahead: ``make_solver``'s ``ahead``), so a
    row's iterates do not depend on which rows share the pool.
    Returns the new ``slots``, the number of pending rows started, whether each local row
    (the ``size`` slots' rows at entry, then the pending ones) finished, and their
    :class:`Equilibrium` (valid where finished).
    """
    dtype = pending[0].dtype
    limit = max_total_steps(opts)
    fn = ScaledProblem.root_fn
    size = slots[2].shape[0]

    # Without per-row parameters the problems differ by their commands only: the scene's
    # parameter-only terms are computed once here, not in every step.
    shared = None if update is not None else ScaledProblem.build(scene, pending[0][0])

    def row_problem(u, p):
        if shared is not None:
            return (
                scene,
                eqx.tree_at(lambda pr: pr.controls, shared, u),
                make_solver(scene, opts, dtype, ahead=True),
            )
        sc = update(scene, p)
        return sc, ScaledProblem.build(sc, u), make_solver(sc, opts, dtype, ahead=True)

    def running(solver, problem, y, st):
        # As optimistix.root_find: stop when the solver terminates, y is not finite or the
        # step budget is spent.
        done, _ = solver.terminate(fn, y, problem, None, st, _TAGS)
        return ~done & jnp.all(jnp.isfinite(y)) & (st.step < limit)

    def step_one(u, p, y, st, held):
        sc, problem, solver = row_problem(u, p)
        run = held & running(solver, problem, y, st)
        y_new, st_new, _ = solver.step(fn, y, problem, None, st, _TAGS)
        y = jnp.where(run, y_new, y)
        st = jtu.tree_map(lambda a, b: jnp.where(run, a, b), st_new, st)
        finished = held & ~running(solver, problem, y, st)
        eq = equilibrium_from(sc, problem, solver, y, st, st.step, opts.tol)
        return y, st, finished, eq

    def start_one(u, p, y):
        _, problem, solver = row_problem(u, p)
        # (eqx.filter_eval_shape keeps the static load sites Python numbers, as root_find does)
        f_struct, aux_struct = eqx.filter_eval_shape(fn, y, problem)
        return solver.init(fn, y, problem, None, f_struct, aux_struct, _TAGS)

    def refill(slots, started):
        # The free slots, in order, take the next pending rows.
        u, p, y, st, row = slots
        free = row < 0
        k = started + jnp.cumsum(free) - 1
        take = free & (k < n_pending)
        k = jnp.clip(k, 0, pending[0].shape[0] - 1)
        u_new, p_new, y_new = jtu.tree_map(lambda x: x[k], pending)
        st_new = jax.vmap(start_one)(u_new, p_new, y_new)

        def pick(a, b):
            return jnp.where(take.reshape((-1,) + (1,) * (a.ndim - 1)), a, b)

        u, p, y, st = jtu.tree_map(pick, (u_new, p_new, y_new, st_new), (u, p, y, st))
        row = jnp.where(take, size + k, row).astype(row.dtype)
        return (u, p, y, st, row), started + jnp.sum(take, dtype=started.dtype)

    def eq_one(u, p, y, st):
        sc, problem, solver = row_problem(u, p)
        return equilibrium_from(sc, problem, solver, y, st, st.step, opts.tol)

    eq_shape = jax.eval_shape(jax.vmap(eq_one), *slots[:4])
    n_local = size + pending[0].shape[0]
    out = jtu.tree_map(lambda s: jnp.zeros((n_local,) + s.shape[1:], s.dtype), eq_shape)
    finished_rows = jnp.zeros(n_local, bool)

    def cond(carry):
        slots, started, _, _, steps = carry
        held = slots[4] >= 0
        # Return to the host for more rows once a slot is free and none is pending.
        fed = drain | (started < n_pending) | jnp.all(held)
        return jnp.any(held) & fed & (steps < max_steps)

    def body(carry):
        (u, p, y, st, row), started, out, finished_rows, steps = carry
        y, st, finished, eq = jax.vmap(step_one)(u, p, y, st, row >= 0)
        at = jnp.where(finished, row, n_local)  # out of range: dropped
        out = jtu.tree_map(lambda o, e: o.at[at].set(e, mode="drop"), out, eq)
        finished_rows = finished_rows.at[at].set(True, mode="drop")
        row = jnp.where(finished, -1, row)
        slots = (u, p, y, st, row)
        # A real branch (its predicate is not batched): most steps hand over no row.
        wanted = jnp.any(finished) & (started < n_pending)
        slots, started = jax.lax.cond(wanted, refill, lambda *a: a, slots, started)
        return slots, started, out, finished_rows, steps + 1

    # Local indices: the row a slot holds at entry is the slot's own index.
    held = slots[4]
    slots = (*slots[:4], jnp.where(held >= 0, jnp.arange(size, dtype=held.dtype), -1))
    slots, started = refill(slots, jnp.asarray(0, jnp.int32))
    carry = (slots, started, out, finished_rows, jnp.asarray(0))
    slots, started, out, finished_rows, _ = jax.lax.while_loop(cond, body, carry)
    return slots, started, finished_rows, out


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


def _initial_slots(scene, opts, size, n_controls, params, dtype, sharding):
    """Placeholder slots of a pool of ``size`` (:func:`_advance`'s ``slots``), every slot free:
    zeros of the commands', parameters' and solver state's shapes. Their values are never read:
    a slot runs only after :func:`_advance` has handed it a row."""
    solver = make_solver(scene, opts, dtype, ahead=True)
    p_shapes = _param_shapes(params)
    zeros = _placeholder(solver, scene.n_dofs, n_controls, p_shapes, np.dtype(dtype), size)
    free = np.full(size, -1, np.int32)
    return jax.device_put((*zeros, free), sharding)


def _param_shapes(params):
    """A row's parameters' shapes and dtypes (hashable), or None without parameters."""
    if params is None:
        return None
    leaves, tree = jtu.tree_flatten(params)
    return tree, tuple((np.shape(x)[1:], np.asarray(x).dtype.str) for x in leaves)


@functools.lru_cache(maxsize=16)
def _placeholder(solver, n: int, n_controls: int, p_shapes, dtype, size: int):
    # Made from shapes alone, once per solver and size: ``solver.init`` run op by op compiled a
    # dozen small programs in every new process and cost more than the steps of a small batch.
    f_struct = jax.ShapeDtypeStruct((n,), dtype)
    shapes = jax.eval_shape(
        lambda y: (y, solver.init(None, y, None, None, f_struct, None, _TAGS)), f_struct
    )
    # Strongly typed, as _advance returns them (a weak type would compile a second version).
    y, state = jtu.tree_map(lambda x: np.zeros((size,) + x.shape, x.dtype), shapes)
    u = np.zeros((size, n_controls), dtype)
    p = _zero_params(p_shapes, size)
    return u, p, y, state


def _zero_params(p_shapes, size):
    if p_shapes is None:
        return np.zeros((size,))
    tree, leaves = p_shapes
    return jtu.tree_unflatten(tree, [np.zeros((size,) + s, d) for s, d in leaves])


class _StartBlocks:
    """Starting points of the rows, computed a block of rows at a time (one compiled call per
    block, not one per slot): the unscaled ``q`` from ``starts`` and the scaled,
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
    # Each pool takes at most its share of the rows: a pool holds the rows it has taken until
    # its slots come free, and one that took the last rows would keep the others waiting.
    share = -(-controls.shape[0] // lanes)
    args = (scene, controls, queue_, share, params, update, opts, size, dtype, sharding)
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
    share,
    params,
    update,
    opts,
    size,
    dtype,
    sharding,
    stop=None,
    ready=None,
):
    """One pool of ``size`` slots taking rows from ``rows_queue`` until it is empty, it has
    taken ``share`` rows, or ``stop`` is set; its calls wait for ``ready`` (the pool compiled, see
    :class:`_RoundCompile`)."""
    slots = _initial_slots(scene, opts, size, controls.shape[1], params, dtype, sharding)
    slot_row = np.full(size, -1)  # the batch row each slot holds
    # Rows taken from the queue and not yet handed to a slot: their rows, q and scaled y.
    pending = (np.zeros(0, int), np.zeros((0, scene.n_dofs)), np.zeros((0, scene.n_dofs)))
    q_start = {}
    while stop is None or not stop.is_set():
        rows, q_new, y_new = rows_queue.take(min(size - len(pending[0]), share))
        share -= len(rows)
        new = (rows, q_new, y_new)
        pending = tuple(np.concatenate([a, b]) for a, b in zip(pending, new, strict=True))
        q_start.update(zip(rows.tolist(), q_new, strict=True))
        drain = share == 0 or not rows_queue.waiting()
        if not len(pending[0]) and not (slot_row >= 0).any():
            return
        if ready is not None:
            ready.wait()
        slots, started, finished, eq = _round(
            scene, opts, update, dtype, sharding, controls, params, slots, pending, size, drain
        )
        local = np.concatenate([slot_row, pending[0], np.full(size - len(pending[0]), -1)])
        held = np.asarray(slots[4])
        slot_row = np.where(held >= 0, local[np.maximum(held, 0)], -1)
        pending = tuple(x[int(started) :] for x in pending)
        done = np.flatnonzero(np.asarray(finished))
        if len(done):
            rows_done = local[done]
            eq_rows = jtu.tree_map(lambda x, d=done: np.asarray(x)[d], eq)
            yield rows_done, np.stack([q_start.pop(r) for r in rows_done.tolist()]), eq_rows


def _round(scene, opts, update, dtype, sharding, controls, params, slots, pending, size, drain):
    """One round of a pool, an :func:`_advance` call: the ``pending`` rows (``(rows, q, y)``,
    at most ``size``) padded to ``size`` and handed over with their commands and parameters."""
    rows, _, y = pending
    n = len(rows)
    take = np.concatenate([rows, np.zeros(size - n, int)]) if n else np.zeros(size, int)
    u = controls[take]
    if params is None:
        p = np.zeros((size,))
    else:
        p = jtu.tree_map(lambda x: np.asarray(x)[take], params)
    y = np.concatenate([y, np.zeros((size - n, y.shape[1]))])
    inputs = (jnp.asarray(u, dtype), jtu.tree_map(jnp.asarray, p), jnp.asarray(y, dtype))
    if sharding is not None:
        inputs = jax.device_put(inputs, sharding)
    return _advance(
        scene,
        opts,
        update,
        slots,
        inputs,
        jnp.asarray(n, jnp.int32),
        jnp.asarray(drain),
        jnp.asarray(MAX_STEPS_PER_CALL, jnp.int32),
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
            slots = _initial_slots(scene, opts, size, controls.shape[1], params, dtype, sharding)
            empty = (np.zeros(0, int), None, np.zeros((0, scene.n_dofs)))
            out = _round(
                scene, opts, update, dtype, sharding, controls, params, slots, empty, size, True
            )
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
