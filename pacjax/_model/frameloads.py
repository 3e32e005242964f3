"""Per-frame changes of a scene in a motion-capture dataset: payload mass, external force, the
base's orientation, the gravity direction, and anything else through a user's hook.

A dataset's payload and force change from frame to frame; the scene gets one
:class:`PointMass` and/or one :class:`PointForce` appended (structure), and
:class:`FrameLoads` writes each frame's values into them (traced leaves, so one compilation
serves every frame). It is the ``update`` of :func:`pacjax.solve_batch`.

Any other per-frame quantity (a temperature-dependent stiffness, a second payload, a tendon's
anchor) travels in the dataset's ``frame_values`` and reaches the scene through a
``frame_update(scene, values) -> scene`` hook: ``values`` holds one frame's entries (traced
arrays), and the hook must be written with ``jax.numpy`` and ``equinox.tree_at`` (it runs
under ``vmap``), e.g.::

    def frame_update(scene, values):
        return eqx.tree_at(lambda s: s.loads[1].mass, scene, values["second_mass"])
"""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .loads import Gravity, PointForce, PointMass
from .scene import Scene


class FrameLoads(eqx.Module):
    """``update(scene, row) -> scene`` putting one frame's values in place."""

    mass_index: int | None = eqx.field(static=True, default=None)
    force_index: int | None = eqx.field(static=True, default=None)
    base_rotation: bool = eqx.field(static=True, default=False)
    gravity_index: int | None = eqx.field(static=True, default=None)
    hook: Callable | None = eqx.field(static=True, default=None)

    def __call__(self, scene: Scene, row) -> Scene:
        if self.base_rotation:
            scene = eqx.tree_at(lambda s: s.robot.base_rotation, scene, row["base_rotation"])
        if self.mass_index is not None:
            scene = eqx.tree_at(lambda s: s.loads[self.mass_index].mass, scene, row["mass"])
        if self.force_index is not None:
            scene = eqx.tree_at(lambda s: s.loads[self.force_index].force, scene, row["force"])
        if self.gravity_index is not None:
            scene = eqx.tree_at(
                lambda s: s.loads[self.gravity_index].direction, scene, row["gravity_direction"]
            )
        if self.hook is not None:
            scene = self.hook(scene, row["values"])
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
        if self.gravity_index is not None:
            out["gravity_direction"] = np.asarray(dataset.gravity_direction, dtype)
        if self.hook is not None:
            out["values"] = {k: np.asarray(v, dtype) for k, v in dataset.frame_values.items()}
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


def with_frame_loads(
    scene: Scene, dataset, frame_update: Callable | None = None
) -> tuple[Scene, FrameLoads]:
    """``scene`` (without marker sites) with the dataset's payload / force appended (values
    0), and their updater (``frame_update``: the hook for the dataset's ``frame_values``)."""
    loads = list(scene.loads)
    mass_index = force_index = gravity_index = None
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
    if dataset.gravity_direction is not None:
        found = [k for k, load in enumerate(loads) if isinstance(load, Gravity)]
        if not found:
            raise ValueError("the dataset has gravity_direction but the scene has no Gravity load")
        gravity_index = found[0]
    _check_hook(dataset.frame_values, frame_update)
    # Marker sites are static structure the solver does not need: dropping them lets scenes
    # that differ only in their markers share one compiled solver.
    new = scene.replace(loads=loads, markers=())
    update = FrameLoads(
        mass_index,
        force_index,
        dataset.base_rotation is not None,
        gravity_index,
        frame_update,
    )
    return new, update


def _check_hook(frame_values, frame_update) -> None:
    if frame_values is not None and frame_update is None:
        raise ValueError(
            f"the dataset has frame_values {sorted(frame_values)} but no frame_update hook puts "
            "them into the scene"
        )
    if frame_update is not None and frame_values is None:
        raise ValueError("frame_update is given but the dataset has no frame_values")
    if frame_update is not None and not callable(frame_update):
        raise TypeError("frame_update must be a callable (scene, values) -> scene")
