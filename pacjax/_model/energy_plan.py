"""The plan of one energy evaluation: which points along the backbone it needs frames at, the
knots of the kinematics they become, and how the load terms find their frames again.

Built once per scene structure (:meth:`pacjax.Scene._energy_plan`); everything here is static
(numpy arrays and Python indices), so the energy kernels index by slices, not gathers.
"""

import copy

import jax
import numpy as np

from .channels import ChannelRouting
from .energy import mass_beyond
from .kinematics import Knots, index_runs
from .loads import PointForce, PointMass
from .tendons import LocalChords, TendonRouting
from .values import concrete


class PointSet:
    """The points ``(segment, s)`` that one energy evaluation needs.

    Points with a concrete ``s`` become knots; a point whose ``s`` is traced (a load site that is
    a scene parameter) is integrated on its own. ``add``/``add_static`` return where the point's
    frame will be in the output of :meth:`evaluate` (static indices: slices, not gathers).
    """

    def __init__(self, n_segments: int):
        self.n_segments = n_segments
        self.segs: list[int] = []
        self.s: list[float] = []
        self.traced: list[tuple[int, jax.Array]] = []

    def __bool__(self):
        return bool(self.segs or self.traced)

    def add_static(self, segs, s) -> slice:
        start = len(self.segs)
        self.segs += [int(k) for k in np.asarray(segs).reshape(-1)]
        self.s += [float(v) for v in np.asarray(s, float).reshape(-1)]
        return slice(start, len(self.segs))

    def add(self, segment: int, s) -> int | tuple:
        value = None if isinstance(s, jax.core.Tracer) else concrete(s)
        if value is not None:
            return self.add_static([segment], [float(value)]).start
        self.traced.append((segment, s))
        return ("traced", len(self.traced) - 1)


class Indexed:
    """Frames indexed by what :class:`PointSet` handed out: ``rows`` maps a static point to
    its row of ``values``; traced points come after the ``n_static`` static ones."""

    def __init__(self, values, rows: dict, n_static: int):
        self.values = values
        self.rows = rows
        self.n_static = n_static

    def __getitem__(self, index):
        if isinstance(index, tuple):
            return self.values[self.n_static + index[1]]
        if isinstance(index, slice):
            first = self.rows[index.start]
            return self.values[first : first + index.stop - index.start]
        return self.values[self.rows[index]]


class EnergyPlan:
    """What the load part of one energy evaluation needs: points, knots and term layout."""

    def __init__(self, scene):
        self.gravity = scene.gravity
        self.points = PointSet(scene.n_segments)
        self.point_masses = scene.loads_of(PointMass) if self.gravity is not None else []
        self.forces = scene.loads_of(PointForce, follower=False)
        self.mass_ids = [self.points.add(pm.segment, pm.s) for pm in self.point_masses]
        # Ring-routed tendons (guide points and chords) and channel-routed ones (per segment).
        self.has_tendons = bool(scene.tendons)
        routing = TendonRouting(scene.tendons)
        self.routing = routing if routing else None
        channels = ChannelRouting(scene.tendons, scene.n_segments)
        self.channels = channels if channels else None
        if self.routing is not None:
            self.guide_ids = self.points.add_static(
                self.routing.point_segment, self.routing.point_s
            )
        self.force_ids = [self.points.add(f.segment, f.s) for f in self.forces]
        self.knots = Knots(
            scene.n_segments,
            np.asarray(self.points.segs, np.int64),
            np.asarray(self.points.s, float),
            scene.kinematics,
        )
        self._robot = scene.robot
        # Tendon chords measured inside their segments when the routing allows it; the load
        # energy then needs world frames only at the mass and force sites.
        self.chords = None
        world = [k for k in self.mass_ids + self.force_ids if not isinstance(k, tuple)]
        if self.routing is not None:
            ids = np.arange(self.guide_ids.start, self.guide_ids.stop)
            knot = self.knots.flat_index[ids] % self.knots.width
            self.chords = LocalChords.build(self.routing, knot, scene.n_segments)
            if self.chords is None:
                world += ids.tolist()
        self.world_points = sorted(set(world))
        flat = self.knots.flat_index[np.asarray(self.world_points, np.int64)]
        self._world_flat = flat
        self.world_runs = index_runs(flat)
        # The knot rows (within a segment) that the load energy reads: the segment ends (for
        # the chaining) and the world points.
        width = self.knots.width
        self.load_rows = np.unique(np.concatenate([flat % width, [width - 1]]).astype(np.int64))
        self.world_segments = [int(self.points.segs[k]) for k in self.world_points]

    def on_load_rows(self) -> "EnergyPlan":
        """This plan for local frames that hold only the knot rows :attr:`load_rows` of each
        segment (``(n_segments, len(load_rows), ...)``): the load energy reads no other row,
        so its derivatives need the kinematics' linearisation there only."""
        other = copy.copy(self)
        width, rows, flat = self.knots.width, self.load_rows, self._world_flat
        other.world_runs = index_runs(
            (flat // width) * len(rows) + np.searchsorted(rows, flat % width)
        )
        return other

    def node_mass(self, dtype):
        """Mass beyond each position node (weights of the by-parts weight), or None."""
        if self.gravity is None:
            return None
        return mass_beyond(self._robot, self.knots.node_s, dtype)
