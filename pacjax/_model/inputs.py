"""Inputs of a solve checked against the scene before any compilation (controls, starting
coordinates), and the scene's leaves prepared for ``jit`` (traced values, constant load sites)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .scene import Scene
from .values import concrete


def frozen(tree):
    """``tree`` with the gradients of its array leaves stopped. Its Python numbers stay Python
    numbers (``jax.lax.stop_gradient`` would make them traced values inside ``jit``): a load
    site made static by :func:`static_load_sites` must stay a knot of the kinematics, or the
    scene's energy plan no longer matches the constants computed with it."""
    return jtu.tree_map(lambda x: jax.lax.stop_gradient(x) if eqx.is_array(x) else x, tree)


def check_int(name: str, value, minimum: int) -> int:
    """``value`` as an int, or a TypeError (not an integer) / ValueError (below ``minimum``)
    naming ``name``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {value!r}")
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    return int(value)


def check_scene(scene) -> None:
    """Raise a TypeError unless ``scene`` is a :class:`pacjax.Scene`."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a pacjax.Scene, got {type(scene).__name__}")


def check_controls(scene: Scene, controls, dtype, batched: bool = False) -> jax.Array:
    """Controls checked against the scene (before any compilation): real, finite, one per
    tendon, tensions not negative; ``(n_tendons,)``, or ``(batch, n_tendons)`` when
    ``batched`` (named ``controls_batch`` then). None: the scene's default controls."""
    name = "controls_batch" if batched else "controls"
    if controls is None:
        return scene.default_controls(dtype)
    arr = None
    if not isinstance(controls, jax.core.Tracer):
        try:
            arr = np.asarray(controls, dtype=float)
        except (TypeError, ValueError):
            raise TypeError(f"{name} must be an array of real numbers, got {controls!r}") from None
    shape = arr.shape if arr is not None else jnp.shape(controls)
    want = ("batch", scene.n_tendons) if batched else (scene.n_tendons,)
    if len(shape) != len(want) or shape[-1] != scene.n_tendons:
        hint = " (use pacjax.solve_batch for many commands)" if len(shape) > len(want) else ""
        raise ValueError(
            f"{name} must have shape {want} (one per tendon), got {shape}{hint}".replace(
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


def check_q(
    scene: Scene, q, dtype, *, name: str = "q0", rows: int | None = None, start: bool = True
):
    """Coordinates checked against the scene (before any compilation): real, finite,
    ``(n_dofs,)``, or also ``(rows, n_dofs)`` when ``rows`` is given (returned broadcast to it,
    as numpy). A ``start`` of a solve must not contract a segment to its stop. None: the rest
    configuration (a batch: None)."""
    if q is None:
        return scene.rest_configuration(dtype) if rows is None else None
    traced = isinstance(q, jax.core.Tracer)
    if not traced:
        try:
            if isinstance(q, (str, bytes)):
                raise TypeError
            q = np.asarray(q, dtype=float)
        except (TypeError, ValueError):
            raise TypeError(f"{name} must be an array of real numbers, got {q!r}") from None
    shape = jnp.shape(q)
    want = [(scene.n_dofs,)] if rows is None else [(scene.n_dofs,), (rows, scene.n_dofs)]
    if shape not in want:
        hint = " (one configuration; vmap for several)" if rows is None and len(shape) > 1 else ""
        shapes = " or ".join(str(w) for w in want)
        raise ValueError(f"{name} must have shape {shapes}{hint}, got {shape}")
    if not traced:
        if not np.all(np.isfinite(q)):
            raise ValueError(f"{name} contains NaN or infinite values")
        if start:
            check_start_contraction(scene, q.reshape(-1, scene.n_dofs))
    if rows is not None:
        return np.broadcast_to(q, (rows, scene.n_dofs))
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
    # In NumPy: the values are known (also inside a jit trace, a q0 closed over by a jitted
    # function), and JAX run op by op compiled each operation in every new process.
    free = scene.free_coordinates()
    shape = (scene.n_segments, scene.dofs_per_segment)
    full = np.zeros((qs.shape[0], shape[0] * shape[1]))
    full[:, slice(None) if free is None else free] = qs
    coords = full.reshape(qs.shape[0], *shape)
    elongation = np.array([[scene.model.elongation(c) for c in row] for row in coords])
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
    """Python numbers put into a scene (e.g. by ``eqx.tree_at``) become arrays, but for load
    sites (:func:`static_load_sites` wants those as Python numbers).

    ``jit`` would treat them as compile-time constants and recompile for every new value. A
    load site is the exception: made an array while tracing (a solve inside the user's ``jit``,
    or inside the inverse solver), it would be a traced site, which costs its own frame
    integration and Hessian block in every solver step.
    """

    def convert(x):
        return jnp.asarray(x, dtype) if _is_number(x) else x

    sites = [getattr(load, "s", None) for load in scene.loads]
    scene = jtu.tree_map(convert, scene)
    loads = tuple(
        eqx.tree_at(lambda x: x.s, load, site) if _is_number(site) else load
        for load, site in zip(scene.loads, sites, strict=True)
    )
    return eqx.tree_at(lambda sc: sc.loads, scene, loads)


def _is_number(x) -> bool:
    return isinstance(x, (float, int)) and not isinstance(x, bool)


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
