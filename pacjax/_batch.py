"""Equilibria for batches of controls: vmapped, chunked, warm-started, sharded across devices.

Each chunk is one compiled, ``vmap``-ed call of the same solver as :func:`solve_equilibrium`, so
results agree with single solves to solver tolerance. Chunks have a fixed size (the last one is
padded), so a batch of any length compiles once. With several devices (``jax.local_devices()``),
every chunk is sharded along the batch axis with ``jax.sharding`` and XLA runs the shards in
parallel. In a multi-host run (``jax.distributed.initialize()``) each process passes the rows
it owns and shards them over its own devices; see docs/multihost.md.
"""

import dataclasses
from collections.abc import Callable, Iterator

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ._equilibrium import (
    SolverOptions,
    as_traced_leaves,
    check_controls,
    check_start_contraction,
    solve_core,
    solver_dtype,
)
from ._scene import Scene
from ._solution import Equilibrium


@eqx.filter_jit
def _solve_chunk(scene, controls, q0, opts, params, update):
    def one(u, q, p):
        sc = scene if update is None else update(scene, p)
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
    scene = as_traced_leaves(scene, dtype)
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
    chunk = -(-chunk // n_devices) * n_devices  # a multiple of the device count
    sharding = _sharding(n_devices)

    done_u: list[np.ndarray] = []
    done_q: list[np.ndarray] = []
    for start in range(0, n, chunk):
        rows = slice(start, min(start + chunk, n))
        u = controls_batch[rows]
        if q0 is not None:
            q = q0[rows]
        elif warm_start and done_u:
            prev_u, prev_q = np.concatenate(done_u), np.concatenate(done_q)
            q = prev_q[_nearest_rows(prev_u, u)]
        else:
            q = np.zeros((u.shape[0], scene.n_dofs))
        p = None if params is None else jtu.tree_map(lambda x, r=rows: x[r], params)
        eq = _run_chunk(scene, u, q, p, update, opts, chunk, dtype, sharding)
        if fallback and opts.method == "ptc" and not np.all(np.asarray(eq.converged)):
            eq = _retry_failed(scene, u, q, p, update, opts, eq, dtype)
        if warm_start:
            ok = np.asarray(eq.converged)
            done_u.append(u[ok])
            done_q.append(np.asarray(eq.q)[ok])
            if sum(len(x) for x in done_u) > 4 * chunk:  # keep the neighbour pool bounded
                done_u, done_q = done_u[-4:], done_q[-4:]
        yield rows, eq


def _pad(x, size):
    if x is None or x.shape[0] == size:
        return x
    pad = np.repeat(x[-1:], size - x.shape[0], axis=0)
    return np.concatenate([x, pad])


def _run_chunk(scene, u, q, p, update, opts, chunk, dtype, sharding):
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
    eq = _solve_chunk(scene, u_pad, q_pad, opts, p_pad, update)
    return jtu.tree_map(lambda x: x[:m], eq)


def _retry_failed(scene, u, q, p, update, opts, eq, dtype):
    """Re-solve the rows that failed with the diffrax flow, keeping whichever converged."""
    bad = np.flatnonzero(~np.asarray(eq.converged))
    flow = dataclasses.replace(opts, method="flow")
    pb = None if p is None else jtu.tree_map(lambda x: x[bad], p)
    retry = _run_chunk(scene, u[bad], q[bad], pb, update, flow, len(bad), dtype, None)
    better = np.asarray(retry.converged)
    rows = bad[better]
    if rows.size == 0:
        return eq
    return jtu.tree_map(lambda a, b: a.at[rows].set(b[better]), eq, retry)


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
        chunk_size: rows per compiled call (memory is bounded by it).
        warm_start: start each row of a chunk from the equilibrium of the nearest command
            solved in earlier chunks (helps on grids and paths).
        devices: number of devices to shard each chunk over (default all).
        progress: show a progress bar (default: when there is more than one chunk).
        fallback: re-solve rows that failed with the diffrax flow.
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
