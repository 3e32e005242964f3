"""The coordinate layout of a scene: which strain model each segment uses, which coordinates
of the kinematics' per-segment layout are coordinates at all, and the rest configuration in it.

The kinematics runs every segment in one model, the family's highest member
(:func:`pacjax._model.strain.common_family`); a lower-order segment's missing coefficients and
an inextensible segment's ``dL`` are pinned at zero there, and the flat coordinates ``q`` hold
the others only.
"""

import functools

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .robot import Robot
from .strain import StrainModel, common_family


def split_models(model, n_segments: int) -> tuple[StrainModel, tuple[StrainModel, ...] | None]:
    """``(Scene.model, Scene.segment_models)`` from one model or one per segment."""
    if isinstance(model, StrainModel) or not isinstance(model, (list, tuple)):
        return model, None
    models = tuple(model)
    if len(models) != n_segments:
        raise ValueError(
            f"Scene.model: one model per segment needs {n_segments}, got {len(models)}"
        )
    for i, m in enumerate(models):
        if not isinstance(m, StrainModel):
            raise TypeError(
                f"Scene.model[{i}] must be a strain model (PCC, PAC, PolynomialCurvature), "
                f"got {m!r}"
            )
    host, models = common_family(models)
    if all(m == host for m in models):
        return host, None
    return host, models


def free_coordinates(robot: Robot, models, host: StrainModel) -> np.ndarray | None:
    """Positions of the coordinates among the flat ``(segments, host dofs)`` layout, or None
    when every entry is a coordinate (read-only: shared between calls)."""
    extensible = tuple(bool(seg.extensible) for seg in robot.segments)
    return _free_index(tuple(models), extensible, host)


@functools.lru_cache(maxsize=256)
def _free_index(models: tuple, extensible: tuple, host: StrainModel) -> np.ndarray | None:
    # Cached: every solve asks for the layout several times while checking its inputs, and
    # the strain models' methods cost tens of microseconds a call (equinox binds each one).
    d = host.dofs_per_segment()
    index = []
    for i, (model, ext) in enumerate(zip(models, extensible, strict=True)):
        own = list(model.embedding(host))
        if not ext:
            own = own[:-1]
        index += [i * d + k for k in own]
    if len(index) == len(models) * d:
        return None
    index = np.asarray(index, np.int64)
    index.flags.writeable = False
    return index


def rest_coordinates(robot: Robot, models, host: StrainModel, dtype) -> Float[Array, "n d"] | None:
    """Every segment's rest curvature in the host's layout (``dL`` 0), or None when every
    segment is straight at rest."""
    if all(seg.rest_curvature is None for seg in robot.segments):
        return None
    rows = []
    for seg, model in zip(robot.segments, models, strict=True):
        row = jnp.zeros(host.dofs_per_segment(), dtype)
        if seg.rest_curvature is not None:
            index = np.asarray(model.embedding(host)[:-1])
            row = row.at[index].set(seg.rest_curvature.astype(dtype))
        rows.append(row)
    return jnp.stack(rows)
