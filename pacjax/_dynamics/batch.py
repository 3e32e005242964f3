"""Many simulations of one scene at once: :func:`simulate_batch`, :func:`pacjax._dynamics.simulate.
simulate`'s program over rows, vectorised a group of rows at a time (all of them on an
accelerator or over several devices, one at a time on a CPU, where each core takes rows as it
finishes one)."""

import os
from concurrent.futures import ThreadPoolExecutor

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._model.inertia import PHI_INERTIA_FACTOR
from .._model.inputs import check_q, check_scene, solver_dtype
from .._model.scene import Scene
from .._statics.batch import check_devices, row_sharding
from .._statics.pool import pad_rows
from .damping import Damping
from .simulate import (
    ATOL,
    RTOL,
    Trajectory,
    aligned_rest_start,
    check_dt0,
    check_qdot,
    check_simulation_controls,
    check_span,
    default_solver,
    integrate,
    prepare,
)

__all__ = ["simulate_batch"]


def simulate_batch(
    scene: Scene,
    t_span,
    controls=None,
    q0=None,
    qdot0=None,
    saveat=None,
    *,
    damping: Damping | None = None,
    solver: diffrax.AbstractSolver | None = None,
    rtol: float = RTOL,
    atol: float = ATOL,
    dt0=None,
    max_steps: int = 100_000,
    phi_inertia: float = PHI_INERTIA_FACTOR,
    devices: int | None = None,
    rows_at_once: int | None = None,
) -> Trajectory:
    """Many simulations of one scene at once (datasets, learning, sweeps over commands).

    Args:
        controls: ``(b, n_tendons)`` constant controls, one row per simulation; or one set for
            all, ``(n_tendons,)`` or a schedule ``t -> (n_tendons,)`` as in :func:`simulate`.
        q0, qdot0: ``(b, n_dofs)`` initial states, or one ``(n_dofs,)`` for all (default
            straight and at rest). The batch size ``b`` is that of the batched arguments (at
            least one of ``controls``, ``q0``, ``qdot0`` has a row per simulation).
        devices: local devices to split the rows over (default all; on a CPU one, since host
            devices share the cores that its rows side by side already keep busy); the rows
            are padded to a multiple of it.
        rows_at_once: rows integrated as one vectorised integration (groups of this many,
            one group after another; over several devices all rows are one group). In a
            group every row accepts and rejects its own steps, the group runs as many as the
            row that needs most, and the rows make their held Jacobians together (when one
            needs it), so a row's steps differ slightly from its own simulation's; one row at
            a time keeps :func:`simulate`'s solver and its own steps, and on a single CPU
            device a thread a core (:func:`cpu_lanes`) runs the one compiled row side by
            side, each thread taking the next row when it finishes one. Default: one on a
            CPU, where vectorising small rows costs more per row than running them one after
            another, and all rows on an accelerator or when the rows are split over several
            devices.
        solver: as in :func:`simulate`.
        Everything else as in :func:`simulate` (no dense output).

    Returns:
        A :class:`Trajectory` whose fields have a leading batch axis (``q``: ``(b, k, n_dofs)``,
        ``result`` and the step counts ``(b,)``). The rows are one vectorised integration:
        every row takes as many steps as the row that needs most (its own steps are accepted,
        or rejected and retried, by its own error estimate), so rows of similar stiffness batch
        best.
    """
    check_scene(scene)
    dtype = solver_dtype(scene)
    t0, t1 = check_span(t_span)
    dt0 = check_dt0(dt0, t0, t1, dtype)
    n, m = scene.n_dofs, scene.n_tendons
    rows = {
        name: np.shape(x)[0]
        for name, x, width in (("controls", controls, m), ("q0", q0, n), ("qdot0", qdot0, n))
        if x is not None and not callable(x) and np.ndim(x) == 2 and np.shape(x)[1] == width
    }
    if not rows:
        raise ValueError(
            f"simulate_batch needs one row per simulation in controls (b, {m}), q0 (b, {n}) "
            f"or qdot0 (b, {n}); got none with two axes (use simulate for one)"
        )
    if len(set(rows.values())) != 1:
        raise ValueError(f"the batched arguments disagree on the batch size: {rows}")
    b = next(iter(rows.values()))
    if b == 0:
        raise ValueError("simulate_batch needs at least one row")

    def rows_of(x, check, name):
        if name in rows:
            checked = []
            for i, row in enumerate(np.asarray(x)):
                try:
                    checked.append(check(row))
                except ValueError as err:
                    raise ValueError(f"{name}[{i}]: {err}") from None
            return jnp.stack(checked)
        one = check(x)
        return jnp.broadcast_to(one, (b,) + one.shape)

    u = controls
    if not callable(controls):
        u = rows_of(controls, lambda x: check_simulation_controls(scene, x, t0, dtype), "controls")
    q = rows_of(q0, lambda x: check_q(scene, x, dtype), "q0")
    v = rows_of(qdot0, lambda x: check_qdot(scene, x, dtype), "qdot0")
    n_devices = check_devices(devices)
    if devices is None and rows_at_once is None and jax.default_backend() == "cpu":
        n_devices = 1
    padded = -(-b // n_devices) * n_devices
    group = _rows_at_once(rows_at_once, padded)
    if n_devices > 1:  # rows sharded over devices are one group: a map over them would gather
        group = padded
    if solver is None:
        solver = default_solver(rtol)
    scene, damping, opts, span, ts = prepare(
        scene, t0, t1, saveat, damping, solver, rtol, atol, max_steps, False, phi_inertia, None
    )
    batched = (u, q, v) if not callable(u) else (q, v)
    batched = jtu.tree_map(lambda x: jnp.asarray(pad_rows(np.asarray(x), padded)), batched)
    sharding = row_sharding(n_devices)
    if sharding is not None:
        batched = jax.device_put(batched, sharding)
    schedule = u if callable(u) else None
    args = (scene, damping, schedule, batched, span, ts, dt0, opts)
    if _side_by_side(group, sharding, args):
        return _rows_side_by_side(*args, rows=b)
    traj = _simulate_rows(*args, group)
    return jtu.tree_map(lambda x: x[:b], traj)


def _side_by_side(group: int, sharding, args) -> bool:
    """Whether rows one at a time run in :func:`cpu_lanes` threads: on a single CPU device,
    where one simulation keeps one core busy (its kernels are small), and not under a
    transformation (a tracer belongs to the thread that traces)."""
    traced = any(isinstance(x, jax.core.Tracer) for x in jtu.tree_leaves(args))
    return group == 1 and sharding is None and jax.default_backend() == "cpu" and not traced


def _rows_side_by_side(scene, damping, schedule, batched, span, ts, dt0, opts, rows: int):
    """The first ``rows`` rows of ``batched``, each simulated as :func:`simulate` runs it (its
    start's alignment, then :func:`integrate`: the same compiled programs, so a batch after a
    simulation of the scene, or a simulation after a batch, compiles nothing), by
    :func:`cpu_lanes` threads that each take the next row as they finish one (rows differ in
    their steps, so halves fixed in advance would leave a core idle). A call a row, not a
    ``lax.map``: XLA:CPU ran a map over one row several times slower than the row alone
    (``benchmarks/RESULTS.md``, "Simulation batches side by side")."""
    batched = jtu.tree_map(np.asarray, batched)

    def run(i):
        row = jtu.tree_map(lambda x: x[i], batched)
        return _one_row(scene, damping, schedule, row, span, ts, dt0, opts)

    first = run(0)  # compiles the programs (or finds them) before the threads share them
    with ThreadPoolExecutor(max_workers=min(cpu_lanes(), rows)) as lanes:
        trajs = [first, *lanes.map(run, range(1, rows))]
    return jtu.tree_map(lambda *xs: jnp.stack(xs), *trajs)


def cpu_lanes() -> int:
    """Rows that run side by side on a CPU: one a core this process may run on. A row's
    kernels are small and run on one thread, so each core takes a row; more threads than
    cores cost nothing measurable (``benchmarks/RESULTS.md``, "Simulation batches: a row a
    core")."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity on this platform (macOS, Windows)
        return os.cpu_count() or 1


def _rows_at_once(rows_at_once: int | None, rows: int) -> int:
    if rows_at_once is None:
        return 1 if jax.default_backend() == "cpu" else rows
    if isinstance(rows_at_once, bool) or not isinstance(rows_at_once, (int, np.integer)):
        raise TypeError(f"rows_at_once must be an integer, got {rows_at_once!r}")
    if rows_at_once < 1:
        raise ValueError(f"rows_at_once must be >= 1, got {rows_at_once}")
    return min(int(rows_at_once), rows)


def _one_row(scene, damping, schedule, row, span, ts, dt0, opts):
    """One row as :func:`simulate` runs it: the start's alignment, then :func:`integrate`."""
    u, q, v = row if schedule is None else (schedule, *row)
    q = aligned_rest_start(scene, u, q, v, span[0])
    return integrate(scene, damping, u, q, v, span, ts, dt0, opts)


@eqx.filter_jit
def _simulate_rows(scene, damping, schedule, batched, span, ts, dt0, opts, group):
    def one(row):
        return _one_row(scene, damping, schedule, row, span, ts, dt0, opts)

    if group >= jtu.tree_leaves(batched)[0].shape[0]:
        return jax.vmap(one)(batched)
    if group == 1:  # a plain loop: lax.map's groups, even of one row, are vmap-ped
        return jax.lax.map(one, batched)
    return jax.lax.map(one, batched, batch_size=group)
