"""The geometry of one configuration as a figure shows it (mm): backbone samples, cross-section
rings, joints, marker sites, tendon paths and tensions, loads. Computed in one kinematics call
per configuration; the figures in :mod:`pacjax.plots.equilibria` and
:mod:`pacjax.plots.animation` draw it."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .._model.loads import PointForce, PointMass, PointMoment
from .._model.query import site_frames, tendon_tensions
from .._model.scene import Scene
from .tendons import tendon_sites

__all__ = ["Drawn", "POINTS_PER_SEGMENT"]

#: Backbone samples per segment; rings on every other one.
POINTS_PER_SEGMENT = 24
_PAYLOAD_MIN_MASS = 0.05  # kg: point masses at least this heavy get a labelled weight arrow


class Drawn:
    """Everything of one configuration that a figure shows, in mm (computed once).

    ``controls`` (one per tendon): the tendons' tensions (N) are computed and shown; None: the
    tendons are drawn without them.
    """

    def __init__(self, scene: Scene, q, controls=None, n_rings_per_segment: int = 8):
        q = np.asarray(q, float)
        if q.shape != (scene.n_dofs,):
            raise ValueError(
                f"configuration has shape {q.shape}, but the scene has {scene.n_dofs} coordinates"
            )
        self.scene = scene
        n = scene.n_segments
        n_points = n * POINTS_PER_SEGMENT + 1
        # Backbone samples evenly spaced in segment + s, as pacjax.backbone; then marker sites,
        # load sites and points along the tendons, all in one kinematics call (compiled once
        # per scene structure: op by op, a few hundred frames take seconds).
        coord = np.linspace(0.0, n, n_points)
        seg = np.minimum(np.floor(coord).astype(np.int32), n - 1)
        s = coord - seg
        sites = list(scene.markers)
        loads = [x for x in scene.loads if isinstance(x, (PointMass, PointForce, PointMoment))]
        tendons = [tendon_sites(t) for t in scene.tendons]
        all_seg = np.concatenate(
            [seg, [x[0] for x in sites], [x.segment for x in loads]] + [t[0] for t in tendons]
        )
        all_s = np.concatenate(
            [s, [x[1] for x in sites], [float(np.asarray(x.s)) for x in loads]]
            + [t[1] for t in tendons]
        )
        n_plain = n_points + len(sites) + len(loads)
        offsets = np.concatenate([np.zeros((n_plain, 3))] + [t[2] for t in tendons])
        pos, rot = site_frames(scene, jnp.asarray(q), all_seg.astype(np.int32), all_s, offsets)
        rot, pos = np.asarray(rot), 1e3 * np.asarray(pos)
        self.points, self.rotations = pos[:n_points], rot[:n_points]
        ends = np.cumsum([n_plain] + [len(t[0]) for t in tendons])
        self.tendon_paths = [pos[a:b] for a, b in zip(ends[:-1], ends[1:], strict=True)]
        self.tensions = None
        if controls is not None and scene.tendons:
            self.tensions = np.asarray(tendon_tensions(scene, jnp.asarray(q), controls), float)
        r0 = np.array([float(np.asarray(x.radius)) for x in scene.robot.segments])
        r1 = np.array(
            [
                r if x.radius_tip is None else float(np.asarray(x.radius_tip))
                for r, x in zip(r0, scene.robot.segments, strict=True)
            ]
        )
        self.radius = 1e3 * (r0[seg] + (r1[seg] - r0[seg]) * s)
        step = max(1, POINTS_PER_SEGMENT // n_rings_per_segment)
        self.ring_index = np.arange(0, n_points, step)
        self.boundary_index = np.arange(0, n_points, POINTS_PER_SEGMENT)
        self.joint_index = self.boundary_index[1:-1]  # between segments (the tip is no joint)
        self.markers = None
        m = len(sites)
        if sites:
            offsets = 1e3 * np.asarray([x[2] for x in sites], float)
            sl = slice(n_points, n_points + m)
            self.markers = pos[sl] + np.einsum("pij,pj->pi", rot[sl], offsets)
        self.loads = self._loads(loads, rot[n_points + m : n_plain], pos[n_points + m : n_plain])

    def ring(self, i: int, n: int = 32) -> np.ndarray:
        """Cross-section circle (n, 3) at backbone point ``i``."""
        theta = np.linspace(0.0, 2 * np.pi, n)
        local = np.stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)], -1)
        return self.points[i] + self.radius[i] * local @ self.rotations[i].T

    def _loads(self, items, rot, pos) -> list[tuple[str, np.ndarray, np.ndarray, str]]:
        """``(kind, point_mm, direction_unit, label)`` for every load worth drawing."""
        out = []
        gravity = self.scene.gravity
        for load, r, p in zip(items, rot, pos, strict=True):
            if isinstance(load, PointMass):
                mass = float(np.asarray(load.mass))
                if gravity is None or mass < _PAYLOAD_MIN_MASS:
                    out.append(("mass", p, np.zeros(3), ""))
                    continue
                direction = np.asarray(gravity.direction, float)
                out.append(("weight", p, direction, f"{1e3 * mass:.0f} g"))
            else:
                vec = np.asarray(load.force if isinstance(load, PointForce) else load.moment)
                vec = r @ vec if load.follower else vec
                size = float(np.linalg.norm(vec))
                if size == 0:
                    continue
                kind = "force" if isinstance(load, PointForce) else "moment"
                unit = "N" if kind == "force" else "N m"
                label = f"{size:.3g} {unit}" + (" (follower)" if load.follower else "")
                out.append((kind, p, vec / size, label))
        return out

    def extent_points(self, arrow_mm: float) -> np.ndarray:
        pts = [self.points, self.points + self.radius[:, None], self.points - self.radius[:, None]]
        for kind, p, d, _ in self.loads:
            if kind in ("weight", "force"):
                pts.append((p + arrow_mm * d)[None])
        return np.concatenate(pts)
