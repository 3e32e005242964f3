"""The checks of a :class:`pacjax._model.scene.Scene`'s fields: each wrong field is a one-line
error naming it, raised when the scene is made, before anything is traced."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .loads import Gravity, PointForce, PointMass, PointMoment
from .robot import Robot
from .strain import StrainModel
from .tendons import Tendon


def sequence_of(owner: str, items, kind: str) -> tuple:
    if isinstance(items, (str, bytes)) or not np.iterable(items) or isinstance(items, eqx.Module):
        raise TypeError(f"{owner} must be a sequence of {kind}, got {type(items).__name__}")
    return tuple(items)


def count_of(owner: str, value) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{owner} must be an integer, got {value!r}")
    return int(value)


def grid_of(owner: str, value) -> tuple[int, int]:
    """A pair of positive integers, as a tuple (a static field must hash)."""
    if isinstance(value, (str, bytes)) or np.ndim(value) != 1 or len(value) != 2:
        raise TypeError(f"{owner} must be a pair of integers (intervals, nodes), got {value!r}")
    pair = tuple(count_of(owner, v) for v in value)
    if min(pair) < 1:
        raise ValueError(f"{owner} must be >= 1 in both entries, got {pair}")
    return pair


def check_fields(scene) -> None:
    """Raise a TypeError or ValueError naming the first wrong field of ``scene``."""
    if not isinstance(scene.robot, Robot):
        raise TypeError(f"Scene.robot must be a Robot, got {type(scene.robot).__name__}")
    if not isinstance(scene.model, StrainModel):
        raise TypeError(
            "Scene.model must be a strain model (PCC, PAC, PolynomialCurvature), "
            f"got {scene.model!r}"
        )
    n = scene.robot.n_segments
    for i, t in enumerate(scene.tendons):
        if not isinstance(t, Tendon):
            raise TypeError(f"Scene.tendons[{i}] must be a Tendon, got {type(t).__name__}")
        if t.segment >= n:
            raise ValueError(
                f"Scene.tendons[{i}] is anchored on segment {t.segment}, but the robot has "
                f"{n} segments (0..{n - 1})"
            )
    if any(t.routing == "channel" for t in scene.tendons):
        q0 = jnp.zeros(scene.model.dofs_per_segment())
        if scene.model.base_rotation(q0) is not None:
            raise ValueError(
                "Scene.tendons: a channel tendon needs frames that run on continuously from "
                "one segment to the next; this model twists each segment's base "
                "(frame='paper'): use frame='torsion_free' or rings"
            )
    kinds = (Gravity, PointMass, PointForce, PointMoment)
    for i, load in enumerate(scene.loads):
        if not isinstance(load, kinds):
            raise TypeError(f"Scene.loads[{i}] must be one of {[k.__name__ for k in kinds]}")
        if not isinstance(load, Gravity) and load.segment >= n:
            raise ValueError(
                f"Scene.loads[{i}] ({type(load).__name__}) is on segment {load.segment}, but "
                f"the robot has {n} segments (0..{n - 1})"
            )
    if sum(isinstance(load, Gravity) for load in scene.loads) > 1:
        raise ValueError("Scene.loads holds more than one Gravity")
    if scene.loads_of(PointMass) and scene.gravity is None:
        raise ValueError("Scene.loads has a PointMass but no Gravity to pull on it")
    # Gauss-Legendre with n points is exact to degree 2n - 1: the elastic energy (degree
    # 2 k in s, + 4 for a taper's r^4, + a profile's) must be integrated exactly, or its
    # Hessian loses rank.
    profile = max(seg.profile_degree() for seg in scene.robot.segments)
    needed = scene.model.strain_degree() + 1 + (profile + 1) // 2
    if scene.quadrature_points < needed:
        raise ValueError(
            f"Scene.quadrature_points must be >= {needed} for this model"
            f"{' with tapered or profiled segments' if profile else ''} (the elastic energy "
            f"is integrated exactly only then), got {scene.quadrature_points}"
        )
    if scene.rotation_substeps is not None and scene.rotation_substeps < 1:
        raise ValueError(f"Scene.rotation_substeps must be >= 1, got {scene.rotation_substeps}")
    for i, (seg, model) in enumerate(zip(scene.robot.segments, scene.models, strict=True)):
        want = model.dofs_per_segment() - 1
        if seg.rest_curvature is not None and seg.rest_curvature.shape != (want,):
            names = ", ".join(model.coordinate_names()[:-1])
            raise ValueError(
                f"Scene.robot.segments[{i}].rest_curvature must hold {want} numbers for "
                f"{type(model).__name__} ({names}), got shape {seg.rest_curvature.shape}"
            )
