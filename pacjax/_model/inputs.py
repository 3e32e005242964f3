"""Inputs of a solve checked against the scene before any compilation (controls, starting
coordinates), and the scene's leaves prepared for ``jit`` (traced values, constant load sites)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .robot import concrete
from .scene import Scene


def check_controls(scene: Scene, controls, dtype, batched: bool = False) -> jax.Array:
    """Validate controls against the scene (before any compilation).

    A single solve takes exactly ``(n_tendons,)``; a batch ``(batch, n_tendons)``.
    """
    if controls is None:
        return scene.default_controls(dtype)
    arr = None
    if not isinstance(controls, jax.core.Tracer):
        try:
            arr = np.asarray(controls, dtype=float)
        except (TypeError, ValueError):
            raise TypeError(f"controls must be real numbers, got {controls!r}") from None
    shape = arr.shape if arr is not None else jnp.shape(controls)
    want = ("batch", scene.n_tendons) if batched else (scene.n_tendons,)
    if len(shape) != len(want) or shape[-1] != scene.n_tendons:
        hint = " (use pacjax.solve_batch for many commands)" if len(shape) > len(want) else ""
        raise ValueError(
            f"controls must have shape {want} (one per tendon), got {shape}{hint}".replace(
                "'batch'", "batch"
            )
        )
    if arr is not None:
        if not np.all(np.isfinite(arr)):
            raise ValueError("controls contain NaN or infinite values")
        for i, t in enumerate(scene.tendons):
            if t.mode == "tension" and np.any(arr[..., i] < 0):
                raise ValueError(
                    f"controls[{i}] is a tension and must be >= 0 (tendons never push)"
                )
    return jnp.asarray(controls, dtype)


def check_q(scene: Scene, q, dtype) -> jax.Array:
    if q is None:
        return scene.zeros(dtype)
    if not isinstance(q, jax.core.Tracer):
        try:
            q = np.asarray(q, dtype=float)
        except (TypeError, ValueError):
            raise TypeError(f"q0 must be an array of real numbers, got {q!r}") from None
    shape = np.shape(q) if not isinstance(q, jax.core.Tracer) else jnp.shape(q)
    if shape != (scene.n_dofs,):
        raise ValueError(f"q0 must have shape ({scene.n_dofs},), got {shape}")
    if not isinstance(q, jax.core.Tracer):
        if not np.all(np.isfinite(np.asarray(q, float))):
            raise ValueError("q0 contains NaN or infinite values")
        check_start_contraction(scene, np.asarray(q, float)[None])
    return jnp.asarray(q, dtype)


def check_start_contraction(scene: Scene, qs: np.ndarray) -> None:
    """Raise a ValueError naming ``q0`` when a start contracts a segment to or past its stop.

    There the energy is infinite (:func:`pacjax._model.energy.contraction_stop_energy`): no solver
    can start from it. ``qs`` is (rows, n_dofs) of known values.
    """
    known = [concrete(seg.contraction_limit) for seg in scene.robot.segments]
    if any(x is None for x in known):
        return
    limits = np.asarray(known, float)
    # Evaluated now even inside a jit trace (a known q0 closed over by a jitted function).
    with jax.ensure_compile_time_eval():
        coords = jax.vmap(scene.coordinates)(jnp.asarray(qs))
        elongation = np.asarray(jax.vmap(jax.vmap(scene.model.elongation))(coords))
    past = -elongation >= limits[None]
    if np.any(past):
        row, seg = np.argwhere(past)[0]
        where = f" (row {row})" if qs.shape[0] > 1 else ""
        raise ValueError(
            f"q0{where} contracts segment {seg} by {-elongation[row, seg]:.6g} m, at or past its "
            f"contraction_limit {float(limits[seg]):.6g} m (infinite energy: no solver can start "
            "there)"
        )


def as_traced_leaves(scene: Scene, dtype) -> Scene:
    """Python numbers put into a scene (e.g. by ``eqx.tree_at``) become arrays.

    ``jit`` would treat them as compile-time constants and recompile for every new value.
    """

    def convert(x):
        if isinstance(x, (float, int)) and not isinstance(x, bool):
            return jnp.asarray(x, dtype)
        return x

    return jtu.tree_map(convert, scene)


def static_load_sites(scene: Scene) -> Scene:
    """Load sites (``s`` of point masses, forces and moments) whose value is known now become
    Python floats, which ``jit`` treats as compile-time constants.

    A known site is a knot of the kinematics, evaluated with the tendon guides for free; a traced
    one costs its own frame integration and its own Hessian block in every solver step (it more
    than doubled the compiled solver of the paper's robot). A new site value compiles again; a
    site set per row (``solve_batch(params=..., update=...)``) or differentiated stays traced.
    """
    loads = []
    for load in scene.loads:
        site = getattr(load, "s", None)
        value = None if site is None or isinstance(site, jax.core.Tracer) else concrete(site)
        if value is not None and value.shape == ():
            load = eqx.tree_at(lambda x: x.s, load, float(value))
        loads.append(load)
    return eqx.tree_at(lambda sc: sc.loads, scene, tuple(loads))


def solver_dtype(scene: Scene):
    """The floating dtype the scene's parameters are stored in."""
    leaves = [x for x in jtu.tree_leaves(scene) if eqx.is_inexact_array(x)]
    return leaves[0].dtype if leaves else jnp.float64
