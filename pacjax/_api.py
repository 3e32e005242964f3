"""Kinematic queries on a solved (or any) configuration: backbone, markers, tip pose."""

import equinox as eqx
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
from jaxtyping import Array, Float

from ._scene import Scene, normalise_sites


def backbone(
    scene: Scene, q: Float[Array, " n_dofs"], n_points: int = 50
) -> tuple[Float[Array, "n_points 3"], Float[Array, "n_points 3 3"]]:
    """Positions (m) and rotations of ``n_points`` frames evenly spaced along the whole robot.

    Points are spaced evenly in the normalised coordinate ``segment + s`` from the base to the
    tip (both included), in the world frame.
    """
    if n_points < 2:
        raise ValueError(f"n_points must be >= 2, got {n_points}")
    n = scene.n_segments
    coord = np.linspace(0.0, n, n_points)
    seg = np.minimum(np.floor(coord).astype(np.int32), n - 1)
    rot, pos = scene.frames(jnp.asarray(q), seg, coord - seg)
    return pos, rot


def markers(scene: Scene, q: Float[Array, " n_dofs"], sites=None) -> Float[Array, "m 3"]:
    """World positions (m) of marker sites ``((segment, s), ...)`` or
    ``((segment, s, offset_xyz), ...)`` with the offset in the local cross-section frame.

    Default: the scene's own ``markers``.
    """
    sites = scene.markers if sites is None else normalise_sites(sites, scene.n_segments)
    if not sites:
        raise ValueError("no marker sites: pass sites= or build the scene with markers=")
    seg = np.asarray([x[0] for x in sites], np.int32)
    s = np.asarray([x[1] for x in sites])
    offsets = np.asarray([x[2] for x in sites])
    q = jnp.asarray(q)
    rot, pos = scene.frames(q, seg, s)
    return pos + jnp.einsum("pij,pj->pi", rot, jnp.asarray(offsets, q.dtype))


def tip_pose(
    scene: Scene, q: Float[Array, " n_dofs"]
) -> tuple[Float[Array, "3"], Float[Array, "3 3"]]:
    """Position (m) and rotation of the tip frame (end of the last segment)."""
    rot, pos = scene.frames(jnp.asarray(q), np.asarray([scene.n_segments - 1]), np.ones(1))
    return pos[0], rot[0]


def astype(tree, dtype):
    """Cast every floating array of a scene (or any pytree) to ``dtype`` (e.g. float32)."""
    return jtu.tree_map(lambda x: x.astype(dtype) if eqx.is_inexact_array(x) else x, tree)


def tendon_tensions(scene: Scene, q, controls) -> Float[Array, " m"]:
    """Tension (N) in every tendon at ``q`` under ``controls``."""
    q = jnp.asarray(q)
    return scene.tendon_tensions(q, jnp.asarray(controls, q.dtype))
