"""Per-frame loads of a motion-capture dataset (payload mass, external force, the base's
orientation) in a scene.

A dataset's payload and force change from frame to frame; the scene gets one
:class:`PointMass` and/or one :class:`PointForce` appended (structure), and
:class:`FrameLoads` writes each frame's values into them (traced leaves, so one compilation
serves every frame). It is the ``update`` of :func:`pacjax.solve_batch`.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .loads import PointForce, PointMass
from .scene import Scene


class FrameLoads(eqx.Module):
    """``update(scene, row) -> scene`` putting ``row["mass"]`` / ``row["force"]`` in place."""

    mass_index: int | None = eqx.field(static=True, default=None)
    force_index: int | None = eqx.field(static=True, default=None)
    base_rotation: bool = eqx.field(static=True, default=False)

    def __call__(self, scene: Scene, row) -> Scene:
        if self.base_rotation:
            scene = eqx.tree_at(lambda s: s.robot.base_rotation, scene, row["base_rotation"])
        if self.mass_index is not None:
            scene = eqx.tree_at(lambda s: s.loads[self.mass_index].mass, scene, row["mass"])
        if self.force_index is not None:
            scene = eqx.tree_at(lambda s: s.loads[self.force_index].force, scene, row["force"])
        return scene

    def rows(self, dataset, dtype=float) -> dict | None:
        """The per-frame values of ``dataset`` as a pytree with a leading frame axis."""
        out = {}
        if self.mass_index is not None:
            out["mass"] = np.asarray(dataset.payload_mass, dtype)
        if self.force_index is not None:
            out["force"] = np.asarray(dataset.force, dtype)
        if self.base_rotation:
            out["base_rotation"] = np.asarray(dataset.base_rotation, dtype)
        return out or None


def _site(site, scene: Scene, name: str) -> tuple[int, float]:
    if site is None:
        return scene.n_segments - 1, 1.0
    seg, s = site[0], site[1]
    if seg >= scene.n_segments:
        raise ValueError(
            f"dataset {name} is on segment {seg}, but the robot has {scene.n_segments} segments"
        )
    return int(seg), float(s)


def with_frame_loads(scene: Scene, dataset) -> tuple[Scene, FrameLoads]:
    """``scene`` (without marker sites) with the dataset's payload / force appended (values
    0), and their updater."""
    loads = list(scene.loads)
    mass_index = force_index = None
    if dataset.payload_mass is not None:
        if scene.gravity is None:
            raise ValueError("the dataset has payload_mass but the scene has no Gravity load")
        seg, s = _site(dataset.payload_site, scene, "payload_site")
        mass_index = len(loads)
        loads.append(PointMass(jnp.zeros(()), seg, s))
    if dataset.force is not None:
        seg, s = _site(dataset.force_site, scene, "force_site")
        force_index = len(loads)
        loads.append(PointForce(jnp.zeros(3), seg, s, follower=dataset.force_follower))
    # Marker sites are static structure the solver does not need: dropping them lets scenes
    # that differ only in their markers share one compiled solver.
    new = Scene(
        scene.robot,
        scene.models,
        tendons=scene.tendons,
        loads=loads,
        quadrature_points=scene.quadrature_points,
        rotation_substeps=scene.rotation_substeps,
    )
    return new, FrameLoads(mass_index, force_index, dataset.base_rotation is not None)
