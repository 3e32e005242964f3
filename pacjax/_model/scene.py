"""A scene: the robot, its strain model, tendons and loads, and nothing else.

A term the scene does not contain is never traced: the checks below are Python ``if``s on the
scene's structure, not zeros multiplied inside a kernel. Array fields (stiffnesses, lengths,
masses, forces, gains) are traced, so a new parameter value never triggers recompilation;
indices, counts, routing and the model are static structure.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import MATMUL_PRECISION
from .channels import ChannelRouting, segment_channel_parts
from .energy import elastic_energy, mass_beyond, moment_cotangent, robot_section_stiffness
from .energy_plan import EnergyPlan
from .kinematics import (
    DEFAULT_KNOT_GRID,
    KinematicsConfig,
    Knots,
    PointLayout,
    contract,
    grid_frames,
    has_plane_derivatives,
    jacobian_and_value,
    knot_frames,
    local_frame,
    segment_knot_curvature,
    segment_knot_frames,
    segment_knot_jacobian,
)
from .layout import free_coordinates, rest_coordinates, split_models
from .load_energy import load_energy
from .loads import Gravity, PointForce, PointMoment
from .robot import Robot
from .rotation import matvec3
from .scene_fields import check_fields, count_of, grid_of, sequence_of
from .sites import normalise_sites
from .strain import StrainModel
from .tendons import Tendon, TendonRouting, segment_tendon_parts, tendon_tensions
from .values import concrete, known_sites


class SceneConstants(eqx.Module):
    """What the energy needs from the scene's parameters alone (not from ``q`` or the controls).

    A solver computes it once per solve (:meth:`Scene.constants`) instead of once per energy
    evaluation inside its loop, where every derivative would trace it again. It stays a
    differentiable function of the parameters, so implicit gradients flow through it.
    """

    bending: Float[Array, "n p"]
    torsion: Float[Array, "n p"]
    node_mass: Float[Array, "n i m"] | None
    body_mass: Float[Array, " n"] | None
    guide_offsets: Float[Array, "g 3"] | None
    rest_lengths: Float[Array, " m"] | None
    channels: dict | None = None  # ChannelRouting.geometry
    rest: Float[Array, "n d"] | None = None  # Scene.rest_coordinates


class Scene(eqx.Module):
    """Everything needed to evaluate the potential energy and the equilibrium residual.

    Args:
        robot: the :class:`Robot`.
        model: the strain model (:class:`PCC`, :class:`PAC`, :class:`PolynomialCurvature`), or
            one per segment from one family (PCC with PAC; polynomials of different orders,
            with PCC among them as ``PolynomialCurvature(0)``, the same kinematics).
            ``Scene.model`` is then the family's highest-order member, in whose coordinates
            the kinematics runs; a lower-order segment has fewer coordinates, as does an
            inextensible one (``Segment(extensible=False)``).
        tendons: :class:`Tendon` s; the controls vector has one entry per tendon, in order.
        loads: :class:`Gravity` (at most one), :class:`PointMass`, :class:`PointForce`,
            :class:`PointMoment`.
        markers: default marker sites ``((segment, s), ...)`` or with a local offset, used by
            :func:`pacjax.markers`, plots and identification.
        quadrature_points: Gauss-Legendre points per segment for the elastic and kinetic
            energies and the lengths of continuous tendon channels (positions and the weight
            are integrated on the kinematics' knots, :mod:`pacjax._model.kinematics`).
        rotation_substeps: Magnus sub-steps per segment (default: exact for the model).
        knot_grid: ``(intervals, nodes)``: at least ``intervals`` knot intervals a segment,
            ``nodes`` Gauss-Legendre position nodes each (default ``(8, 4)``, round-off;
            :func:`pacjax.simulate` takes :data:`pacjax.dynamics.KNOT_GRID`).
    """

    robot: Robot
    model: StrainModel
    segment_models: tuple[StrainModel, ...] | None = eqx.field(static=True, default=None)
    tendons: tuple[Tendon, ...] = ()
    loads: tuple = ()
    markers: tuple = eqx.field(static=True, default=())
    quadrature_points: int = eqx.field(static=True, default=8)
    rotation_substeps: int | None = eqx.field(static=True, default=None)
    knot_grid: tuple[int, int] | None = eqx.field(static=True, default=None)

    def __init__(
        self,
        robot,
        model,
        tendons=(),
        loads=(),
        markers=(),
        quadrature_points=8,
        rotation_substeps=None,
        knot_grid=None,
    ):
        if not isinstance(robot, Robot):
            raise TypeError(f"Scene.robot must be a Robot, got {type(robot).__name__}")
        self.robot = robot
        self.model, self.segment_models = split_models(model, robot.n_segments)
        self.tendons = sequence_of("Scene.tendons", tendons, "Tendons")
        self.loads = sequence_of("Scene.loads", loads, "loads")
        self.markers = normalise_sites(markers, robot.n_segments, "Scene.markers")
        self.quadrature_points = count_of("Scene.quadrature_points", quadrature_points)
        self.rotation_substeps = (
            None
            if rotation_substeps is None
            else count_of("Scene.rotation_substeps", rotation_substeps)
        )
        self.knot_grid = None if knot_grid is None else grid_of("Scene.knot_grid", knot_grid)

    def __check_init__(self):
        check_fields(self)

    # ----------------------------------------------------------------------------- structure
    def loads_of(self, kind, follower=None) -> list:
        return [
            x
            for x in self.loads
            if isinstance(x, kind) and (follower is None or x.follower == follower)
        ]

    @property
    def gravity(self) -> Gravity | None:
        found = self.loads_of(Gravity)
        return found[0] if found else None

    @property
    def n_segments(self) -> int:
        return self.robot.n_segments

    @property
    def models(self) -> tuple[StrainModel, ...]:
        """The strain model of every segment."""
        return self.segment_models or (self.model,) * self.n_segments

    @property
    def dofs_per_segment(self) -> int:
        """Coordinates per segment of :attr:`model` (the kinematics' layout, pinned ones
        included: see :meth:`free_coordinates`)."""
        return self.model.dofs_per_segment()

    def free_coordinates(self) -> np.ndarray | None:
        """Positions of the coordinates among the flat ``(segments, dofs_per_segment)``
        layout, or None when every one is a coordinate.

        A lower-order segment's missing coefficients and an inextensible segment's ``dL`` are
        pinned at zero: not coordinates at all (not solved for, not in ``q``)."""
        return free_coordinates(self.robot, self.models, self.model)

    @property
    def n_dofs(self) -> int:
        free = self.free_coordinates()
        return self.n_segments * self.dofs_per_segment if free is None else len(free)

    @property
    def n_tendons(self) -> int:
        return len(self.tendons)

    @property
    def is_conservative(self) -> bool:
        """True when every load derives from the potential energy (no follower force, no moment)."""
        return not (self.loads_of(PointForce, follower=True) or self.loads_of(PointMoment))

    def replace(self, **changes) -> "Scene":
        """A copy of the scene with some of the constructor's arguments changed."""
        model = self.model if self.segment_models is None else self.segment_models
        kept = ("robot", "tendons", "loads", "markers", "quadrature_points", "rotation_substeps")
        args = {k: getattr(self, k) for k in (*kept, "knot_grid")}
        return Scene(**(args | {"model": model} | changes))

    @property
    def kinematics(self) -> KinematicsConfig:
        substeps = self.rotation_substeps or self.model.exact_rotation_substeps()
        return KinematicsConfig(substeps, self.knot_grid or DEFAULT_KNOT_GRID)

    def coordinates(self, q: Float[Array, " n_dofs"]) -> Float[Array, "n d"]:
        """Flat coordinates as a (segments, :attr:`dofs_per_segment`) matrix, pinned ones 0."""
        free = self.free_coordinates()
        shape = (self.n_segments, self.dofs_per_segment)
        if free is None:
            return q.reshape(shape)
        full = jnp.zeros(q.shape[:-1] + (shape[0] * shape[1],), q.dtype)
        return full.at[..., free].set(q).reshape(q.shape[:-1] + shape)

    def free_part(self, coords: Float[Array, "*b n d"]) -> Float[Array, "*b n_dofs"]:
        """The coordinates of a (segments, :attr:`dofs_per_segment`) matrix: the inverse of
        :meth:`coordinates` on its image."""
        flat = coords.reshape(coords.shape[:-2] + (-1,))
        free = self.free_coordinates()
        return flat if free is None else flat[..., free]

    def coordinate_names(self) -> tuple[str, ...]:
        names = self.model.coordinate_names()
        full = [f"{name}[{i}]" for i in range(self.n_segments) for name in names]
        free = self.free_coordinates()
        return tuple(full) if free is None else tuple(full[k] for k in free)

    def coordinate_scale(self, dtype=float) -> Float[Array, " n_dofs"]:
        """A natural size per coordinate: 1 for strains and angles, ``L`` (m) for ``dL``."""
        d = self.dofs_per_segment
        lengths = self.robot.stacked("length").astype(dtype)
        scale = jnp.ones((self.n_segments, d), dtype).at[:, d - 1].set(lengths)
        return self.free_part(scale)

    def rest_coordinates(self, dtype=float) -> Float[Array, "n d"] | None:
        """Every segment's :attr:`Segment.rest_curvature` in :attr:`model`'s layout (``dL``
        0), or None when every segment is straight at rest."""
        return rest_coordinates(self.robot, self.models, self.model, dtype)

    def rest_configuration(self, dtype=float) -> Float[Array, " n_dofs"]:
        """The unloaded configuration: every segment at its rest curvature, ``dL = 0``."""
        rest = self.rest_coordinates(dtype)
        return self.zeros(dtype) if rest is None else self.free_part(rest)

    def elastic_stiffness_diagonal(self, dtype=float) -> Float[Array, " n_dofs"]:
        """Stiffness scale per coordinate: the diagonal of the elastic Hessian at rest (> 0).

        Used to scale the residual and as the damping of the flow. A coordinate that is not a
        strain (PAC's bending-plane angle) takes the scale the model gives it.
        """
        x0 = jnp.zeros(self.n_segments * self.dofs_per_segment, dtype)

        def energy(x):
            return self.coords_elastic_energy(x.reshape(self.n_segments, -1))

        diag = jnp.diag(jax.hessian(energy)(x0)).reshape(self.n_segments, -1)
        return self.free_part(self.model.stiffness_scale(diag))

    # ----------------------------------------------------------------------------- kinematics
    def frames(self, q, segment, s):
        """World rotations (p, 3, 3) and positions (p, 3) at points ``(segment[k], s[k])``.

        ``segment`` must be concrete (Python ints or a numpy array); ``s`` may be traced. Points
        whose ``s`` is concrete take the knot path of :mod:`pacjax._model.kinematics`.
        """
        q = jnp.asarray(q)
        segment = np.asarray(segment).reshape(-1)
        s_value = None if isinstance(s, jax.core.Tracer) else concrete(s)
        if s_value is not None:
            return self._knot_frames(q, segment, np.broadcast_to(s_value, segment.shape))
        layout = PointLayout(self.n_segments, segment)
        rot, pos = grid_frames(
            self.model,
            self.coordinates(q),
            self.robot.stacked("length").astype(q.dtype),
            self.robot.base_rotation,
            self.robot.base_position,
            layout.grid(jnp.asarray(s, q.dtype).reshape(-1), q.dtype),
            self.kinematics,
        )
        return layout.select(rot), layout.select(pos)

    def _knot_frames(self, q, segment: np.ndarray, s: np.ndarray):
        """Frames at points with concrete ``s`` (the knot path of
        :mod:`pacjax._model.kinematics`)."""
        knots = Knots(self.n_segments, segment, s, self.kinematics)
        rot, pos = self.knot_grid_frames(q, knots)
        return knots.select(rot), knots.select(pos)

    def knot_grid_frames(
        self, q: Float[Array, " n_dofs"], knots: Knots
    ) -> tuple[Float[Array, "n k 3 3"], Float[Array, "n k 3"]]:
        """World rotations and positions (m) at every knot of ``knots``, segment by segment."""
        rot, pos, _ = knot_frames(
            self.model,
            self.coordinates(q),
            self.robot.stacked("length").astype(q.dtype),
            self.robot.base_rotation,
            self.robot.base_position,
            knots,
        )
        return rot, pos

    def tendon_lengths(self, q: Float[Array, " n_dofs"]) -> Float[Array, " m"]:
        """Length (m) of every tendon at configuration ``q``."""
        lengths = self._channel_lengths(self.coordinates(q))
        routing = TendonRouting(self.tendons)
        if routing:
            rot, pos = self.frames(q, routing.point_segment, routing.point_s)
            offsets = routing.local_offsets(self.tendons, q.dtype)
            lengths = lengths + routing.lengths(pos + matvec3(rot, offsets))
        return lengths

    def rest_tendon_lengths(self, dtype=float) -> Float[Array, " m"]:
        """Length (m) of every tendon on the robot at rest (straight unless a segment has a
        rest curvature)."""
        if self.rest_coordinates(dtype) is not None:
            return self.tendon_lengths(self.rest_configuration(dtype))
        segment_lengths = self.robot.stacked("length").astype(dtype)
        lengths = self._channel_lengths(jnp.zeros((self.n_segments, self.dofs_per_segment), dtype))
        routing = TendonRouting(self.tendons)
        if routing:
            lengths = lengths + routing.rest_lengths(self.tendons, segment_lengths)
        return lengths

    def _channel_lengths(self, coords: Float[Array, "n d"]) -> Float[Array, " m"]:
        """The channel tendons' lengths (m) at per-segment coordinates ``coords`` (zero for
        the ring tendons)."""
        dtype = coords.dtype
        channels = ChannelRouting(self.tendons, self.n_segments)
        if not channels:
            return jnp.zeros(self.n_tendons, dtype)
        parts = jax.vmap(self.segment_channel_lengths)(
            coords,
            self.robot.stacked("length").astype(dtype),
            channels.geometry(self.tendons, dtype),
        )
        return jnp.sum(parts, axis=0)

    def segment_channel_lengths(self, qi, length, channels) -> Float[Array, " m"]:
        """One segment's part of every channel tendon's length (m)."""
        return segment_channel_parts(self.model, qi, length, channels, self.quadrature_points)

    def tendon_tensions(self, q, controls) -> Float[Array, " m"]:
        """Tension (N) of every tendon at configuration ``q`` under ``controls``."""
        return tendon_tensions(
            self.tendons, self.tendon_lengths(q), self.rest_tendon_lengths(q.dtype), controls
        )

    # ----------------------------------------------------------------------------- energy
    def constants(self, dtype=float) -> SceneConstants:
        """The parameter-only part of the energy (see :class:`SceneConstants`)."""
        bending, torsion = robot_section_stiffness(self.robot, self.quadrature_points, dtype)
        plan = self.energy_plan()
        node_mass = body_mass = offsets = rest = channels = None
        if plan is not None and plan.gravity is not None:
            node_mass = plan.node_mass(dtype)
            body_mass = mass_beyond(self.robot, np.zeros(self.n_segments), dtype)
        if plan is not None and plan.routing is not None:
            offsets = plan.routing.local_offsets(self.tendons, dtype)
        if plan is not None and plan.channels is not None:
            channels = plan.channels.geometry(self.tendons, dtype)
        if plan is not None and plan.has_tendons:
            rest = self.rest_tendon_lengths(dtype)
        return SceneConstants(
            bending,
            torsion,
            node_mass,
            body_mass,
            offsets,
            rest,
            channels,
            self.rest_coordinates(dtype),
        )

    def elastic_energy(
        self, q: Float[Array, " n_dofs"], consts: SceneConstants | None = None
    ) -> Float[Array, ""]:
        """Elastic energy (J) at ``q``, measured from the rest curvature."""
        return self.coords_elastic_energy(self.coordinates(q), consts)

    def coords_elastic_energy(
        self, coords: Float[Array, "n d"], consts: SceneConstants | None = None
    ) -> Float[Array, ""]:
        """:meth:`elastic_energy` at per-segment coordinates (:meth:`coordinates`' layout)."""
        if consts is None:
            stiffness, rest = None, self.rest_coordinates(coords.dtype)
        else:
            stiffness, rest = (consts.bending, consts.torsion), consts.rest
        return elastic_energy(
            self.model, self.robot, coords, self.quadrature_points, stiffness, rest
        )

    def potential_energy(
        self, q: Float[Array, " n_dofs"], controls, consts: SceneConstants | None = None
    ) -> Float[Array, ""]:
        """Potential energy ``V(q; theta, u)`` (J): elastic, gravity, tendons, world forces.

        ``consts``: :meth:`constants` when already computed (solvers pass it).
        """
        consts = self.constants(q.dtype) if consts is None else consts
        energy = self.elastic_energy(q, consts)
        plan = self.energy_plan()
        if plan is None:
            return energy
        local = self._local_kinematics(self.coordinates(q), plan, consts)
        return energy + self.load_energy(local, controls, plan, consts)

    def _segment_frames(self, qi, length, knots, node_weights):
        """One segment's knot frames and weighted tangent integral in its base frame."""
        return segment_knot_frames(
            self.model,
            qi,
            length,
            knots,
            node_weights,
            interval_nodes=self.kinematics.interval_nodes,
        )

    def segment_frames_jacobian(self, qi, length, knots, node_weights):
        """``(d frames / d qi, frames)`` of :meth:`_segment_frames`: point by point along the
        bending and plane angles for PCC/PAC
        (:func:`pacjax._model.kinematics.segment_knot_jacobian`),
        by forward derivatives otherwise."""
        if has_plane_derivatives(self.model):
            nodes = self.kinematics.interval_nodes
            return segment_knot_jacobian(
                self.model, qi, length, knots, node_weights, interval_nodes=nodes
            )
        return jacobian_and_value(
            lambda y: self._segment_frames(y, length, knots, node_weights), qi
        )

    def segment_frames_curvature(self, qi, lam, length, knots, node_weights):
        """Hessian along ``qi`` of ``lam . frames(qi)`` (``lam`` a cotangent of
        :meth:`_segment_frames`' value)."""
        if has_plane_derivatives(self.model):
            nodes = self.kinematics.interval_nodes
            return segment_knot_curvature(
                self.model, qi, length, knots, node_weights, lam, interval_nodes=nodes
            )
        return jax.hessian(
            lambda y: contract(lam, self._segment_frames(y, length, knots, node_weights))
        )(qi)

    def _segment_local(self, qi, length, knots, node_weights, chords, channels):
        """One segment's part of the local kinematics: its knot frames and weighted tangent
        integral in its base frame (:meth:`_segment_frames`), and its tendons' lengths inside
        it, from local chords and channels (None when it has neither)."""
        rot, pos, moment = self._segment_frames(qi, length, knots, node_weights)
        parts = None if chords is None else segment_tendon_parts(rot, pos, chords)
        if channels is not None:
            in_channels = self.segment_channel_lengths(qi, length, channels)
            parts = in_channels if parts is None else parts + in_channels
        return rot, pos, moment, parts

    def segment_inputs(self, plan: EnergyPlan, consts: SceneConstants, dtype):
        """Per-segment arguments of :meth:`_segment_local` (leading axis: segments)."""
        lengths = self.robot.stacked("length").astype(dtype)
        grid = jnp.asarray(plan.knots.s, dtype)
        chords = None if plan.chords is None else plan.chords.inputs(consts.guide_offsets)
        return lengths, grid, consts.node_mass, chords, consts.channels

    # The energy is E_el(q) + Psi(L_0(q_0), ..., L_n-1(q_n-1)): each segment's local kinematics
    # L_i (frames at its knots in its own base frame) depends on its own coordinates only, and
    # Psi (chaining, tendons, weight, loads) is cheap. _hessian.py uses this structure.
    def energy_plan(self) -> EnergyPlan | None:
        """The points and terms the load part of the energy needs (None: elastic only)."""
        plan = EnergyPlan(self)
        return plan if plan.points or plan.gravity is not None or plan.has_tendons else None

    def _local_kinematics(
        self, coords: Float[Array, "n d"], plan: EnergyPlan, consts: SceneConstants
    ):
        """Per-segment local frames at the knots, and the local frames of traced load sites."""
        segments = jax.vmap(self._segment_local)(
            coords, *self.segment_inputs(plan, consts, coords.dtype)
        )
        traced = tuple(self.traced_local_frame(coords[k], k, s_k) for k, s_k in plan.points.traced)
        return segments, traced

    def traced_local_frame(self, qk, k: int, s_k):
        length = self.robot.segments[k].length.astype(qk.dtype)
        return local_frame(self.model, qk, length, jnp.asarray(s_k, qk.dtype), self.kinematics)

    def load_energy(
        self, local, controls, plan: EnergyPlan, consts: SceneConstants
    ) -> Float[Array, ""]:
        """``Psi``: gravity, tendon and world-force energy (J) from the local kinematics
        (:func:`pacjax._model.load_energy.load_energy`)."""
        return load_energy(self, local, controls, plan, consts)

    def nonconservative_forces(self, q: Float[Array, " n_dofs"]) -> Float[Array, " n_dofs"] | None:
        """Generalised forces of follower forces and point moments (None when there are none)."""
        followers = self.loads_of(PointForce, follower=True)
        moments = self.loads_of(PointMoment)
        if not (followers or moments):
            return None
        items = followers + moments
        segs = np.asarray([x.segment for x in items])
        # Known sites take the knot path: stacked with jnp they would be traced, and the frames
        # would be found on the general grid path, which costs more per row.
        ss = known_sites([x.s for x in items], q.dtype)
        (rot, pos), pullback = jax.vjp(lambda q_: self.frames(q_, segs, ss), q)
        dtype = q.dtype
        cot_pos = jnp.zeros_like(pos)
        cot_rot = jnp.zeros_like(rot)
        if followers:
            local = jnp.stack([f.force for f in followers]).astype(dtype)
            world = matvec3(rot[: len(followers)], local)
            cot_pos = cot_pos.at[: len(followers)].set(world)
        for k, m in enumerate(moments, start=len(followers)):
            moment = m.moment.astype(dtype)
            if m.follower:
                moment = jnp.matmul(rot[k], moment, precision=MATMUL_PRECISION)
            cot_rot = cot_rot.at[k].set(moment_cotangent(moment, rot[k]))
        (generalised,) = pullback((cot_rot, cot_pos))
        return generalised

    def residual(
        self, q: Float[Array, " n_dofs"], controls, consts: SceneConstants | None = None
    ) -> Float[Array, " n_dofs"]:
        """Equilibrium residual ``F(q) = grad V(q) - Q_nc(q)`` (generalised forces)."""
        force = jax.grad(self.potential_energy)(q, controls, consts)
        extra = self.nonconservative_forces(q)
        return force if extra is None else force - extra

    # ----------------------------------------------------------------------------- conversion
    def zeros(self, dtype=float) -> Float[Array, " n_dofs"]:
        """The straight configuration (the rest one unless a segment has a rest curvature:
        :meth:`rest_configuration`)."""
        return jnp.zeros(self.n_dofs, dtype)

    def default_controls(self, dtype=float) -> Float[Array, " m"]:
        return jnp.zeros(self.n_tendons, dtype)
