"""Synthetic motion-capture data from a higher-fidelity version of a scene.

The honest stand-in for real logs: the data come from a richer model than the one being fitted
(cubic curvature per segment, optionally each segment split into several, stiffening with
contraction), seen through an unknown rigid transform (the mocap frame is not the robot's world
frame), with Gaussian marker noise and dropped markers.
"""

from __future__ import annotations

import dataclasses
import warnings

import jax
import numpy as np

from .._model.frameloads import with_frame_loads
from .._model.loads import Gravity, PointForce, PointMass, PointMoment
from .._model.robot import ExponentialStiffening, Robot, Segment
from .._model.scene import Scene
from .._model.sites import normalise_sites
from .._model.strain import PolynomialCurvature, StrainModel
from .._model.tendons import Tendon
from .._statics.batch import solve_batch
from .dataset import MocapDataset


def _piece(site_seg: int, s: float, n: int, anchor: bool = False) -> tuple[int, float]:
    """A site ``(segment, s)`` of the coarse robot on the robot with ``n`` pieces a segment."""
    j = min(int(np.floor(s * n)), n - 1)
    local = s * n - j
    if anchor and local == 0.0 and j > 0:  # an anchor needs s in (0, 1]
        j, local = j - 1, 1.0
    return site_seg * n + j, float(local)


def high_fidelity(
    scene: Scene,
    *,
    model: StrainModel | None = None,
    subdivisions: int = 1,
    stiffening_rate: float | None = None,
) -> Scene:
    """A richer version of ``scene`` with the same physical parameters.

    Args:
        scene: the scene.
        model: strain model of the result (default ``PolynomialCurvature(order=3)``).
        subdivisions: split every segment into this many equal pieces (same ``EI``, ``GJ``,
            density; axial stiffness times ``subdivisions``: springs in series). Only for robots
            without Bowden tendons (a Bowden cable enters at its own segment's base).
        stiffening_rate: add :class:`ExponentialStiffening` with this rate to segments without
            a stiffening law.
    """
    model = PolynomialCurvature(order=3) if model is None else model
    n = int(subdivisions)
    if n < 1:
        raise ValueError(f"subdivisions must be >= 1, got {subdivisions}")
    if n > 1 and any(t.bowden for t in scene.tendons):
        raise ValueError(
            "subdivisions > 1 is not possible with Bowden tendons (a Bowden tendon enters at the "
            "base of its own segment); use subdivisions=1 and a higher-order model"
        )
    if n > 1 and any(seg.profile is not None for seg in scene.robot.segments):
        raise ValueError(
            "high_fidelity: subdivisions > 1 with a SectionProfile (its polynomial is in the "
            "whole segment's s); use subdivisions=1 and a higher-order model"
        )
    if any(seg.rest_curvature is not None for seg in scene.robot.segments):
        raise ValueError(
            "high_fidelity: a segment has a rest_curvature, which is written in the scene's "
            "strain model's coordinates and has no counterpart in another model or on pieces"
        )
    segments = []
    for seg in scene.robot.segments:
        law = seg.stiffening
        if law is None and stiffening_rate is not None:
            law = ExponentialStiffening(stiffening_rate)
        segments += [_segment_piece(seg, j, n, law) for j in range(n)]
    robot = Robot(segments, scene.robot.base_rotation, scene.robot.base_position)
    tendons = [_tendon_on_pieces(t, n) for t in scene.tendons]
    loads = [x for x in (_load_on_pieces(load, n) for load in scene.loads) if x is not None]
    markers = [(*_piece(seg, s, n), off) for seg, s, off in scene.markers]
    quad = max(scene.quadrature_points, model.strain_degree() + 3)
    return Scene(
        robot, model, tendons=tendons, loads=loads, markers=markers, quadrature_points=quad
    )


def _segment_piece(seg: Segment, j: int, n: int, law) -> Segment:
    """Piece ``j`` of ``n`` of a segment, with the stiffening law ``law``."""
    start, end = np.asarray(j / n), np.asarray((j + 1) / n)
    bending = seg.bending_profile(start)
    density = seg.area_profile(start)
    return Segment(
        length=seg.length / n,
        bending_stiffness=seg.bending_stiffness * (1.0 if bending is None else bending),
        axial_stiffness=seg.axial_stiffness * n,
        torsion_stiffness=seg.torsion_stiffness * (1.0 if bending is None else bending),
        linear_density=seg.linear_density * (1.0 if density is None else density),
        radius=seg.radius_at(start),
        radius_tip=seg.radius_at(end) if seg.tapered else None,
        inner_radius=seg.inner_radius_at(start),
        inner_radius_tip=seg.inner_radius_at(end) if seg.tapered else None,
        stiffening=law,
        contraction_limit=seg.contraction_limit / n,
        extensible=seg.extensible,
        profile=seg.profile,
    )


def _tendon_on_pieces(t: Tendon, n: int) -> Tendon:
    """A tendon on the robot with ``n`` pieces a segment (anchor and guides moved)."""
    seg, s = _piece(t.segment, t.s, n, anchor=True)
    guides = None
    if t.routing == "rings":
        guides = sorted(
            {round(g * n - j, 12) for g in t.guides for j in range(n) if j <= g * n <= j + 1}
        )
    return Tendon(
        seg,
        t.angle,
        t.offset,
        s=s,
        offset_end=t.offset_end,
        bowden=t.bowden,
        guides=guides,
        mode=t.mode,
        gain=t.gain,
        routing=t.routing,
        angle_end=t.angle_end,
    )


def _load_on_pieces(load, n: int):
    """A load on the robot with ``n`` pieces a segment (gravity as it is; None for a kind of
    load that is not carried over)."""
    if isinstance(load, Gravity):
        return load
    seg, s = _piece(load.segment, float(load.s), n)
    if isinstance(load, PointMass):
        return PointMass(load.mass, seg, s)
    if isinstance(load, PointForce):
        return PointForce(load.force, seg, s, follower=load.follower)
    if isinstance(load, PointMoment):
        return PointMoment(load.moment, seg, s, follower=load.follower)
    return None


@dataclasses.dataclass
class SyntheticTruth:
    """What produced a synthetic dataset.

    Attributes:
        scene: the scene that generated the data (the high-fidelity one).
        q: (frames, n_dofs) its equilibria.
        markers: (frames, m, 3) noise-free marker positions in the scene's world frame (m).
        rotation, translation: the transform ``x_mocap = rotation @ x_world + translation``.
        dropped: indices (into the requested controls) of frames whose truth did not converge
            to a stable equilibrium and were left out.
    """

    scene: Scene
    q: np.ndarray
    markers: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    dropped: np.ndarray


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix."""
    w, x, y, z = (q := rng.normal(size=4)) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def synthetic_mocap(
    scene: Scene,
    controls,
    *,
    sites=None,
    payload_mass=None,
    payload_site=None,
    force=None,
    force_site=None,
    force_follower: bool = False,
    base_rotation=None,
    gravity_direction=None,
    frame_values=None,
    frame_update=None,
    noise: float = 1e-3,
    dropout: float = 0.0,
    transform="random",
    orientations: bool = False,
    orientation_noise: float = 0.01,
    exact: bool = False,
    model: StrainModel | None = None,
    subdivisions: int = 1,
    stiffening_rate: float | None = None,
    seed: int = 0,
    **solver_options,
) -> tuple[MocapDataset, SyntheticTruth]:
    """A synthetic motion-capture dataset of ``scene`` (the ground truth's parameters).

    Args:
        scene: the robot with the true parameters.
        controls: (frames, n_tendons) commands.
        sites: marker sites (default: the scene's markers).
        payload_mass, payload_site, force, force_site, force_follower: per-frame loads, as
            in :meth:`MocapDataset.from_arrays`.
        base_rotation, gravity_direction, frame_values: per-frame base and gravity
            directions and other values, as in :meth:`MocapDataset.from_arrays`.
        frame_update: the hook that puts ``frame_values`` into the scene (as in
            :func:`pacjax.identify`).
        noise: standard deviation (m) of the Gaussian noise on each marker coordinate.
        dropout: probability that a marker is missing in a frame (NaN).
        transform: ``"random"`` (uniform random rotation, translation within 1 m), None
            (identity: mocap frame = world frame), or ``(rotation, translation)``.
        orientations: also record the rotation at every site (with ``orientation_noise`` rad).
        exact: generate with ``scene`` itself (the fitted model can match the data exactly);
            otherwise with :func:`high_fidelity` (``model``, ``subdivisions``,
            ``stiffening_rate``).
        seed: random seed.
        **solver_options: for :func:`pacjax.solve_batch`.
    """
    rng = np.random.default_rng(seed)
    controls, sites = _check_request(scene, controls, sites, noise, dropout)
    # A provisional dataset (noise-free placeholders) carries and validates the frame loads.
    template = MocapDataset.from_arrays(
        controls,
        np.zeros((controls.shape[0], len(sites), 3)),
        sites,
        payload_mass,
        payload_site=payload_site,
        force=force,
        force_site=force_site,
        force_follower=force_follower,
        base_rotation=base_rotation,
        gravity_direction=gravity_direction,
        frame_values=frame_values,
    )
    truth_scene = _with_markers(scene, sites)
    if not exact:
        truth_scene = high_fidelity(
            truth_scene, model=model, subdivisions=subdivisions, stiffening_rate=stiffening_rate
        )
    loaded, q, ok, frames = _truth_equilibria(
        scene, truth_scene, template, controls, frame_update, solver_options
    )
    world, rots = _site_poses(frames, truth_scene.markers, q)
    rotation, translation = _mocap_transform(transform, rng)
    measured = _measured_markers(world, rotation, translation, noise, dropout, rng)
    ori = None
    if orientations:
        ori = _measured_orientations(rotation, rots, orientation_noise, rng)
    dataset = _kept_frames(template, np.flatnonzero(ok), measured, ori)
    truth = SyntheticTruth(truth_scene, q, world, rotation, translation, np.flatnonzero(~ok))
    return dataset, truth


def _check_request(scene: Scene, controls, sites, noise, dropout):
    """The checked controls (frames, n_tendons) and marker sites (default: the scene's)."""
    controls = np.asarray(controls, float)
    if controls.ndim != 2 or controls.shape[1] != scene.n_tendons:
        raise ValueError(
            f"controls must have shape (frames, {scene.n_tendons}), got {controls.shape}"
        )
    sites = scene.markers if sites is None else normalise_sites(sites, scene.n_segments)
    if not sites:
        raise ValueError("no marker sites: pass sites= or give the scene markers")
    if not (noise >= 0 and 0 <= dropout < 1):
        raise ValueError("noise must be >= 0 and dropout in [0, 1)")
    return controls, sites


def _truth_equilibria(
    scene: Scene, truth_scene: Scene, template, controls, frame_update, solver_options
):
    """The truth's equilibria of every frame: ``(the truth with the frame loads, q of the
    frames that converged to a stable equilibrium, the mask of those frames)``."""
    loaded, frame_loads = with_frame_loads(
        truth_scene, _remap_sites(template, scene, truth_scene), frame_update
    )
    rows = frame_loads.rows(template)
    eq = solve_batch(
        loaded,
        controls,
        params=rows,
        update=frame_loads if rows is not None else None,
        **{"chunk_size": 16, **solver_options},
    )
    ok = np.asarray(eq.converged) & np.asarray(eq.stable)
    if not ok.any():
        raise ValueError("no frame of the ground truth converged to a stable equilibrium")
    if not ok.all():
        warnings.warn(  # at the caller of synthetic_mocap
            f"{int((~ok).sum())} synthetic frame(s) did not converge; left out", stacklevel=3
        )
    # Each kept frame's scene (its loads and base orientation), for the marker poses.
    frames = [
        loaded if rows is None else frame_loads(loaded, jax.tree.map(lambda v, i=i: v[i], rows))
        for i in np.flatnonzero(ok)
    ]
    return loaded, np.asarray(eq.q)[ok], ok, frames


def _site_poses(frames: list, markers, q) -> tuple[np.ndarray, np.ndarray]:
    """(frames, m, 3) positions and (frames, m, 3, 3) rotations at the marker sites (world),
    each frame in its own scene."""
    from .._model.query import site_frames

    segs = np.asarray([x[0] for x in markers])
    ss = np.asarray([x[1] for x in markers])
    offs = np.asarray([x[2] for x in markers])
    world, rots = [], []
    for scene_k, qk in zip(frames, q, strict=True):
        pos, rot = site_frames(scene_k, qk, segs, ss, offs)
        world.append(np.asarray(pos))
        rots.append(np.asarray(rot))
    return np.stack(world), np.stack(rots)


def _mocap_transform(transform, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``(rotation, translation)`` from the world frame to the mocap frame."""
    if transform is None:
        return np.eye(3), np.zeros(3)
    if isinstance(transform, str) and transform == "random":
        return random_rotation(rng), rng.uniform(-1.0, 1.0, 3)
    rotation, translation = (np.asarray(x, float) for x in transform)
    return rotation, translation


def _measured_markers(world, rotation, translation, noise, dropout, rng) -> np.ndarray:
    """Marker positions in the mocap frame with Gaussian noise, and NaN where dropped (at least
    one marker is kept in every frame)."""
    measured = world @ rotation.T + translation + noise * rng.normal(size=world.shape)
    if dropout > 0:
        miss = rng.random(measured.shape[:2]) < dropout
        miss[np.arange(len(miss)), rng.integers(0, miss.shape[1], len(miss))] = False
        measured[miss] = np.nan
    return measured


def _measured_orientations(rotation, rots, orientation_noise, rng) -> np.ndarray:
    """Site rotations in the mocap frame, turned by random kicks of ``orientation_noise`` rad."""
    ori = np.einsum("ij,fmjk->fmik", rotation, rots)
    if orientation_noise > 0:
        from .._model.rotation import exp_so3

        kicks = orientation_noise * rng.normal(size=ori.shape[:2] + (3,))
        ori = np.einsum(
            "fmij,fmjk->fmik", ori, np.asarray([[exp_so3(w) for w in f] for f in kicks])
        )
    return ori


def _kept_frames(template: MocapDataset, keep, measured, orientations) -> MocapDataset:
    """The dataset of the frames ``keep``: the template's controls and loads, the measurements."""
    kept = template[keep]
    return MocapDataset.from_arrays(
        kept.controls,
        measured,
        kept.sites,
        kept.payload_mass,
        payload_site=kept.payload_site,
        force=kept.force,
        force_site=kept.force_site,
        force_follower=kept.force_follower,
        orientations=orientations,
        base_rotation=kept.base_rotation,
        gravity_direction=kept.gravity_direction,
        frame_values=kept.frame_values,
    )


def _with_markers(scene: Scene, sites) -> Scene:
    return scene.replace(markers=sites)


def _remap_sites(dataset: MocapDataset, coarse: Scene, fine: Scene) -> MocapDataset:
    """The dataset's payload and force sites on the (possibly subdivided) truth robot."""
    n = fine.n_segments // coarse.n_segments
    if n == 1:
        return dataset
    last = (coarse.n_segments - 1, 1.0)
    ps = _piece(*(dataset.payload_site or last), n) if dataset.payload_mass is not None else None
    fs = _piece(*(dataset.force_site or last), n) if dataset.force is not None else None
    return dataclasses.replace(dataset, payload_site=ps, force_site=fs)
