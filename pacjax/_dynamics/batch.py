"""Many simulations of one scene at once: :func:`simulate_batch`, one vectorised integration of
:func:`pacjax._dynamics.simulate.simulate`'s program, its rows split over the local devices."""

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
    Trajectory,
    aligned_rest_start,
    check_qdot,
    check_simulation_controls,
    check_span,
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
    rtol: float = 1e-7,
    atol: float = 1e-9,
    dt0=None,
    max_steps: int = 100_000,
    phi_inertia: float = PHI_INERTIA_FACTOR,
    devices: int | None = None,
) -> Trajectory:
    """Many simulations of one scene at once (datasets, learning, sweeps over commands).

    Args:
        controls: ``(b, n_tendons)`` constant controls, one row per simulation; or one set for
            all, ``(n_tendons,)`` or a schedule ``t -> (n_tendons,)`` as in :func:`simulate`.
        q0, qdot0: ``(b, n_dofs)`` initial states, or one ``(n_dofs,)`` for all (default
            straight and at rest). The batch size ``b`` is that of the batched arguments (at
            least one of ``controls``, ``q0``, ``qdot0`` has a row per simulation).
        devices: local devices to split the rows over (default all); the rows are padded to a
            multiple of it.
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
    scene, damping, opts, span, ts = prepare(
        scene, t0, t1, saveat, damping, solver, rtol, atol, max_steps, False, phi_inertia, None
    )
    n_devices = check_devices(devices)
    padded = -(-b // n_devices) * n_devices
    batched = (u, q, v) if not callable(u) else (q, v)
    batched = jtu.tree_map(lambda x: jnp.asarray(pad_rows(np.asarray(x), padded)), batched)
    sharding = row_sharding(n_devices)
    if sharding is not None:
        batched = jax.device_put(batched, sharding)
    dt0 = None if dt0 is None else jnp.asarray(dt0, dtype)
    schedule = u if callable(u) else None
    traj = _simulate_rows(scene, damping, schedule, batched, span, ts, dt0, opts)
    return jtu.tree_map(lambda x: x[:b], traj)


@eqx.filter_jit
def _simulate_rows(scene, damping, schedule, batched, span, ts, dt0, opts):
    def one(row):
        u, q, v = row if schedule is None else (schedule, *row)
        q = aligned_rest_start(scene, u, q, v, span[0])
        return integrate(scene, damping, u, q, v, span, ts, dt0, opts)

    return jax.vmap(one)(batched)
