"""Kinematic queries on a solved (or any) configuration: backbone, markers, tip pose."""

import equinox as eqx
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
from jaxtyping import Array, Float

from .._jit import jit
from .inputs import check_controls, check_q, check_scene
from .rotation import matvec3
from .scene import Scene
from .sites import normalise_sites


@jit
def _frames(scene: Scene, q, segments: tuple[int, ...], s: tuple[float, ...], offsets):
    # Sites are static: the frames come from the same knot kinematics as the energy.
    rot, pos = scene.frames(q, np.asarray(segments, np.int64), np.asarray(s, float))
    return pos + matvec3(rot, offsets.astype(q.dtype)), rot


def _configuration(scene: Scene, q) -> Array:
    """``q`` checked against the scene (before any compilation): shape, real, finite; a
    floating ``q`` keeps its dtype."""
    check_scene(scene)
    if q is None:
        raise TypeError(f"q must be an array of {scene.n_dofs} coordinates, got None")
    floating = hasattr(q, "dtype") and jnp.issubdtype(q.dtype, jnp.floating)
    return check_q(scene, q, q.dtype if floating else None, name="q", start=False)


def site_frames(scene: Scene, q, segments, s, offsets=None):
    """Compiled frame query (segments static, everything else traced)."""
    q = _configuration(scene, q)
    s = tuple(float(v) for v in np.asarray(s, float).reshape(-1))
    offsets = jnp.zeros((len(segments), 3), q.dtype) if offsets is None else offsets
    return _frames(scene, q, tuple(int(k) for k in segments), s, jnp.asarray(offsets, q.dtype))


def backbone(
    scene: Scene, q: Float[Array, " n_dofs"], n_points: int = 50
) -> tuple[Float[Array, "n_points 3"], Float[Array, "n_points 3 3"]]:
    """Positions (m) and rotations of ``n_points`` frames evenly spaced along the whole robot.

    Points are spaced evenly in the normalised coordinate ``segment + s`` from the base to the
    tip (both included), in the world frame.
    """
    check_scene(scene)
    if isinstance(n_points, (bool, np.bool_)) or not isinstance(n_points, (int, np.integer)):
        raise TypeError(f"n_points must be an integer, got {n_points!r}")
    if n_points < 2:
        raise ValueError(f"n_points must be >= 2, got {n_points}")
    n = scene.n_segments
    coord = np.linspace(0.0, n, n_points)
    seg = np.minimum(np.floor(coord).astype(np.int32), n - 1)
    return site_frames(scene, q, seg, coord - seg)


def markers(scene: Scene, q: Float[Array, " n_dofs"], sites=None) -> Float[Array, "m 3"]:
    """World positions (m) of marker sites ``((segment, s), ...)`` or
    ``((segment, s, offset_xyz), ...)`` with the offset in the local cross-section frame.

    Default: the scene's own ``markers``.
    """
    check_scene(scene)
    sites = scene.markers if sites is None else normalise_sites(sites, scene.n_segments)
    if not sites:
        raise ValueError("no marker sites: pass sites= or build the scene with markers=")
    seg = np.asarray([x[0] for x in sites], np.int32)
    s = np.asarray([x[1] for x in sites])
    offsets = np.asarray([x[2] for x in sites])
    return site_frames(scene, q, seg, s, offsets)[0]


def tip_pose(
    scene: Scene, q: Float[Array, " n_dofs"]
) -> tuple[Float[Array, "3"], Float[Array, "3 3"]]:
    """Position (m) and rotation of the tip frame (end of the last segment)."""
    pos, rot = site_frames(scene, q, [scene.n_segments - 1], np.ones(1))
    return pos[0], rot[0]


def astype(tree, dtype):
    """Cast every floating array of a scene (or any pytree) to ``dtype`` (e.g. float32)."""
    try:
        floating = jnp.issubdtype(dtype, jnp.floating)
    except TypeError:
        floating = False
    if not floating:
        raise TypeError(f"dtype must be a floating dtype (float32, float64), got {dtype!r}")
    return jtu.tree_map(lambda x: x.astype(dtype) if eqx.is_inexact_array(x) else x, tree)


def tendon_tensions(scene: Scene, q, controls) -> Float[Array, " m"]:
    """Tension (N) in every tendon at ``q`` under ``controls``."""
    q = _configuration(scene, q)
    controls = check_controls(scene, controls, q.dtype)
    if not scene.tendons:
        return jnp.zeros((0,), q.dtype)
    return _tensions(scene, q, jnp.asarray(controls, q.dtype))


@jit
def _tensions(scene, q, controls):
    return scene.tendon_tensions(q, controls)
