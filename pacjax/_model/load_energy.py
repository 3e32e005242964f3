"""The scene's load energy ``Psi``: gravity on the body and its point masses, the tendons and
world-fixed forces, from the segments' local kinematics chained into the world."""

import jax.numpy as jnp
from jaxtyping import Array, Float

from .._config import MATMUL_PRECISION
from .energy_plan import EnergyPlan, Indexed
from .kinematics import chain_segments, take_runs
from .rotation import matmul3, matvec3
from .tendons import tendon_energy


def load_energy(scene, local, controls, plan: EnergyPlan, consts) -> Float[Array, ""]:
    """``Psi``: gravity, tendon and world-force energy (J) of ``scene`` from its local
    kinematics ``local`` (:meth:`pacjax._model.scene.Scene.energy_plan`'s points, their
    frames chained to the world here), under ``controls``."""
    (rot, pos, moment, parts), traced = local
    dtype = rot.dtype
    base_rot, base_pos = chain_segments(
        rot[:, -1], pos[:, -1], scene.robot.base_rotation, scene.robot.base_position
    )
    # World frames of the points that need them (static slices, no gather).
    segs = plan.world_segments + [k for k, _ in plan.points.traced]
    local_rot = [r[None] for r, _ in traced]
    local_pos = [p[None] for _, p in traced]
    if plan.world_points:
        local_rot.insert(0, take_runs(rot, plan.world_runs))
        local_pos.insert(0, take_runs(pos, plan.world_runs))
    rows = {k: i for i, k in enumerate(plan.world_points)}
    rot_at = pos_at = Indexed(None, rows, len(plan.world_points))
    if segs:
        frame_rot = jnp.stack([base_rot[k] for k in segs])
        frame_pos = jnp.stack([base_pos[k] for k in segs])
        local_rot = jnp.concatenate(local_rot)
        local_pos = jnp.concatenate(local_pos)
        rot_at = Indexed(matmul3(frame_rot, local_rot), rows, len(plan.world_points))
        pos_at = Indexed(frame_pos + matvec3(frame_rot, local_pos), rows, len(plan.world_points))
    energy = jnp.zeros((), dtype)
    if plan.gravity is not None:
        accel = plan.gravity.acceleration.astype(dtype)
        # The body's first mass moment sum_i int rho A L p ds (kg m), by parts.
        body = jnp.sum(consts.body_mass[:, None] * base_pos + matvec3(base_rot, moment), axis=0)
        energy = energy - jnp.matmul(body, accel, precision=MATMUL_PRECISION)
        for pm, k in zip(plan.point_masses, plan.mass_ids, strict=True):
            energy = energy - pm.mass.astype(dtype) * jnp.dot(
                pos_at[k], accel, precision=MATMUL_PRECISION
            )
    if plan.has_tendons:
        # Local chords and channels as per-segment parts; chords that span a segment
        # without a ring at its end in the world.
        lengths = jnp.zeros(scene.n_tendons, dtype) if parts is None else jnp.sum(parts, axis=0)
        if plan.routing is not None and plan.chords is None:
            sl = plan.guide_ids
            guides = pos_at[sl] + matvec3(rot_at[sl], consts.guide_offsets)
            lengths = lengths + plan.routing.lengths(guides)
        energy = energy + tendon_energy(scene.tendons, lengths, consts.rest_lengths, controls)
    for f, k in zip(plan.forces, plan.force_ids, strict=True):
        energy = energy - jnp.sum(f.force.astype(dtype) * pos_at[k])
    return energy
