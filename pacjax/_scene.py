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

from ._energy import elastic_energy, gravity_masses, moment_cotangent
from ._kinematics import KinematicsConfig, PointLayout, grid_frames
from ._loads import Gravity, PointForce, PointMass, PointMoment
from ._robot import Robot
from ._rotation import matvec3
from ._strain import StrainModel
from ._tendons import Tendon, TendonRouting, tendon_energy, tendon_tensions

Site = tuple  # (segment, s) or (segment, s, (ox, oy, oz))


def normalise_sites(sites, n_segments: int, owner: str = "sites") -> tuple:
    """Validate marker sites and return them as ``((segment, s, (ox, oy, oz)), ...)``."""
    if isinstance(sites, (str, bytes)) or not np.iterable(sites):
        raise TypeError(f"{owner} must be a sequence of (segment, s) sites, got {sites!r}")
    out = []
    for i, site in enumerate(sites):
        if not isinstance(site, (tuple, list)) or len(site) not in (2, 3):
            raise ValueError(
                f"{owner}[{i}] must be (segment, s) or (segment, s, offset_xyz), got {site!r}"
            )
        seg, s = site[0], site[1]
        if (
            not isinstance(seg, (int, np.integer))
            or isinstance(seg, (bool, np.bool_))
            or not 0 <= seg < n_segments
        ):
            raise ValueError(
                f"{owner}[{i}]: segment {seg!r} does not exist (robot has {n_segments})"
            )
        if not _is_real(s) or not (np.isfinite(s) and 0.0 <= s <= 1.0):
            raise ValueError(f"{owner}[{i}]: s must lie in [0, 1], got {s!r}")
        offset = site[2] if len(site) == 3 else (0.0, 0.0, 0.0)
        if (
            not np.iterable(offset)
            or len(offset) != 3
            or not all(_is_real(v) for v in offset)
            or not np.all(np.isfinite(np.asarray(offset, float)))
        ):
            raise ValueError(f"{owner}[{i}]: offset must be 3 finite numbers, got {offset!r}")
        offset = tuple(float(v) for v in offset)
        out.append((int(seg), float(s), offset))
    return tuple(out)


def _is_real(x) -> bool:
    """A plain real number (Python or numpy scalar, or a 0-d array), not a bool or a string."""
    if isinstance(x, (bool, np.bool_)) or np.ndim(x) != 0:
        return False
    return np.issubdtype(np.asarray(x).dtype, np.floating) or np.issubdtype(
        np.asarray(x).dtype, np.integer
    )


def _sequence(owner: str, items, kind: str) -> tuple:
    if isinstance(items, (str, bytes)) or not np.iterable(items) or isinstance(items, eqx.Module):
        raise TypeError(f"{owner} must be a sequence of {kind}, got {type(items).__name__}")
    return tuple(items)


def _count(owner: str, value) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{owner} must be an integer, got {value!r}")
    return int(value)


class Scene(eqx.Module):
    """Everything needed to evaluate the potential energy and the equilibrium residual.

    Args:
        robot: the :class:`Robot`.
        model: the strain model (:class:`PCC`, :class:`PAC`, :class:`PolynomialCurvature`).
        tendons: :class:`Tendon` s; the controls vector has one entry per tendon, in order.
        loads: :class:`Gravity` (at most one), :class:`PointMass`, :class:`PointForce`,
            :class:`PointMoment`.
        markers: default marker sites ``((segment, s), ...)`` or with a local offset, used by
            :func:`pacjax.markers`, plots and identification.
        quadrature_points: Gauss-Legendre points per segment for positions, the elastic energy
            and the distributed weight.
        rotation_substeps: Magnus sub-steps per segment (default: exact for the model).
    """

    robot: Robot
    model: StrainModel
    tendons: tuple[Tendon, ...] = ()
    loads: tuple = ()
    markers: tuple = eqx.field(static=True, default=())
    quadrature_points: int = eqx.field(static=True, default=8)
    rotation_substeps: int | None = eqx.field(static=True, default=None)

    def __init__(
        self,
        robot,
        model,
        tendons=(),
        loads=(),
        markers=(),
        quadrature_points=8,
        rotation_substeps=None,
    ):
        if not isinstance(robot, Robot):
            raise TypeError(f"Scene.robot must be a Robot, got {type(robot).__name__}")
        self.robot = robot
        self.model = model
        self.tendons = _sequence("Scene.tendons", tendons, "Tendons")
        self.loads = _sequence("Scene.loads", loads, "loads")
        self.markers = normalise_sites(markers, robot.n_segments, "Scene.markers")
        self.quadrature_points = _count("Scene.quadrature_points", quadrature_points)
        self.rotation_substeps = (
            None
            if rotation_substeps is None
            else _count("Scene.rotation_substeps", rotation_substeps)
        )

    def __check_init__(self):
        if not isinstance(self.robot, Robot):
            raise TypeError(f"Scene.robot must be a Robot, got {type(self.robot).__name__}")
        if not isinstance(self.model, StrainModel):
            raise TypeError(
                "Scene.model must be a strain model (PCC, PAC, PolynomialCurvature), "
                f"got {self.model!r}"
            )
        n = self.robot.n_segments
        for i, t in enumerate(self.tendons):
            if not isinstance(t, Tendon):
                raise TypeError(f"Scene.tendons[{i}] must be a Tendon, got {type(t).__name__}")
            if t.segment >= n:
                raise ValueError(
                    f"Scene.tendons[{i}] is anchored on segment {t.segment}, but the robot has "
                    f"{n} segments (0..{n - 1})"
                )
        kinds = (Gravity, PointMass, PointForce, PointMoment)
        for i, load in enumerate(self.loads):
            if not isinstance(load, kinds):
                raise TypeError(f"Scene.loads[{i}] must be one of {[k.__name__ for k in kinds]}")
            if not isinstance(load, Gravity) and load.segment >= n:
                raise ValueError(
                    f"Scene.loads[{i}] ({type(load).__name__}) is on segment {load.segment}, but "
                    f"the robot has {n} segments (0..{n - 1})"
                )
        if sum(isinstance(load, Gravity) for load in self.loads) > 1:
            raise ValueError("Scene.loads holds more than one Gravity")
        if self._of(PointMass) and self.gravity is None:
            raise ValueError("Scene.loads has a PointMass but no Gravity to pull on it")
        # Gauss-Legendre with n points is exact to degree 2n - 1: the elastic energy (degree
        # 2 k in s, + 4 for a taper's r^4) must be integrated exactly, or its Hessian loses rank.
        tapered = any(seg.radius_tip is not None for seg in self.robot.segments)
        needed = self.model.strain_degree() + 1 + (2 if tapered else 0)
        if self.quadrature_points < needed:
            raise ValueError(
                f"Scene.quadrature_points must be >= {needed} for this model"
                f"{' with tapered segments' if tapered else ''} (the elastic energy is integrated "
                f"exactly only then), got {self.quadrature_points}"
            )
        if self.rotation_substeps is not None and self.rotation_substeps < 1:
            raise ValueError(f"Scene.rotation_substeps must be >= 1, got {self.rotation_substeps}")

    # ----------------------------------------------------------------------------- structure
    def _of(self, kind, follower=None) -> list:
        return [
            x
            for x in self.loads
            if isinstance(x, kind) and (follower is None or x.follower == follower)
        ]

    @property
    def gravity(self) -> Gravity | None:
        found = self._of(Gravity)
        return found[0] if found else None

    @property
    def n_segments(self) -> int:
        return self.robot.n_segments

    @property
    def dofs_per_segment(self) -> int:
        return self.model.dofs_per_segment()

    @property
    def n_dofs(self) -> int:
        return self.n_segments * self.dofs_per_segment

    @property
    def n_tendons(self) -> int:
        return len(self.tendons)

    @property
    def is_conservative(self) -> bool:
        """True when every load derives from the potential energy (no follower force, no moment)."""
        return not (self._of(PointForce, follower=True) or self._of(PointMoment))

    @property
    def kinematics(self) -> KinematicsConfig:
        substeps = self.rotation_substeps or self.model.exact_rotation_substeps()
        return KinematicsConfig(self.quadrature_points, substeps)

    def coordinates(self, q: Float[Array, " n_dofs"]) -> Float[Array, "n d"]:
        """Flat coordinates as a (segments, coordinates per segment) matrix."""
        return q.reshape(self.n_segments, self.dofs_per_segment)

    def coordinate_names(self) -> tuple[str, ...]:
        names = self.model.coordinate_names()
        return tuple(f"{name}[{i}]" for i in range(self.n_segments) for name in names)

    def coordinate_scale(self, dtype=float) -> Float[Array, " n_dofs"]:
        """A natural size per coordinate: 1 for strains and angles, ``L`` (m) for ``dL``."""
        d = self.dofs_per_segment
        lengths = self.robot.stacked("length").astype(dtype)
        scale = jnp.ones((self.n_segments, d), dtype).at[:, d - 1].set(lengths)
        return scale.reshape(-1)

    def elastic_stiffness_diagonal(self, dtype=float) -> Float[Array, " n_dofs"]:
        """Stiffness scale per coordinate: the diagonal of the elastic Hessian at rest (> 0).

        Used to scale the residual and as the damping of the flow. A coordinate that is not a
        strain (PAC's bending-plane angle) takes the scale the model gives it.
        """
        q0 = jnp.zeros(self.n_dofs, dtype)
        diag = jnp.diag(jax.hessian(self.elastic_energy)(q0))
        return self.model.stiffness_scale(self.coordinates(diag)).reshape(-1)

    # ----------------------------------------------------------------------------- kinematics
    def frames(self, q, segment, s):
        """World rotations (p, 3, 3) and positions (p, 3) at points ``(segment[k], s[k])``.

        ``segment`` must be concrete (Python ints or a numpy array); ``s`` may be traced.
        """
        q = jnp.asarray(q)
        layout = PointLayout(self.n_segments, np.asarray(segment).reshape(-1))
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

    def tendon_lengths(self, q: Float[Array, " n_dofs"]) -> Float[Array, " m"]:
        """Length (m) of every tendon at configuration ``q``."""
        routing = TendonRouting(self.tendons)
        rot, pos = self.frames(q, routing.point_segment, routing.point_s)
        offsets = routing.local_offsets(self.tendons, q.dtype)
        return routing.lengths(pos + matvec3(rot, offsets))

    def rest_tendon_lengths(self, dtype=float) -> Float[Array, " m"]:
        """Length (m) of every tendon on the straight robot at rest."""
        routing = TendonRouting(self.tendons)
        return routing.rest_lengths(self.tendons, self.robot.stacked("length").astype(dtype))

    def tendon_tensions(self, q, controls) -> Float[Array, " m"]:
        """Tension (N) of every tendon at configuration ``q`` under ``controls``."""
        return tendon_tensions(
            self.tendons, self.tendon_lengths(q), self.rest_tendon_lengths(q.dtype), controls
        )

    # ----------------------------------------------------------------------------- energy
    def elastic_energy(self, q: Float[Array, " n_dofs"]) -> Float[Array, ""]:
        return elastic_energy(self.model, self.robot, self.coordinates(q), self.quadrature_points)

    def potential_energy(self, q: Float[Array, " n_dofs"], controls) -> Float[Array, ""]:
        """Potential energy ``V(q; theta, u)`` (J): elastic, gravity, tendons, world forces."""
        dtype = q.dtype
        energy = self.elastic_energy(q)

        # Every point the energy needs, evaluated in one batched kinematics call.
        segs: list[int] = []
        ss: list = []
        gravity = self.gravity
        masses = point_masses = routing = None
        forces = self._of(PointForce, follower=False)
        if gravity is not None:
            g_segs, g_s, masses = gravity_masses(self.robot, self.quadrature_points, dtype)
            segs += g_segs
            ss.append(jnp.asarray(g_s, dtype))
            point_masses = self._of(PointMass)
            segs += [pm.segment for pm in point_masses]
            ss += [pm.s.astype(dtype)[None] for pm in point_masses]
        if self.tendons:
            routing = TendonRouting(self.tendons)
            tendon_start = len(segs)
            segs += routing.point_segment.tolist()
            ss.append(jnp.asarray(routing.point_s, dtype))
        force_start = len(segs)
        segs += [f.segment for f in forces]
        ss += [f.s.astype(dtype)[None] for f in forces]
        if not segs:
            return energy

        rot, pos = self.frames(q, np.asarray(segs), jnp.concatenate(ss))
        if gravity is not None:
            accel = gravity.acceleration.astype(dtype)
            if point_masses:
                masses = jnp.concatenate(
                    [masses, jnp.stack([pm.mass for pm in point_masses]).astype(dtype)]
                )
            energy = energy - jnp.sum(masses * (pos[: len(masses)] @ accel))
        if routing is not None:
            sl = slice(tendon_start, tendon_start + len(routing.point_s))
            offsets = routing.local_offsets(self.tendons, dtype)
            points = pos[sl] + matvec3(rot[sl], offsets)
            lengths = routing.lengths(points)
            rest = routing.rest_lengths(self.tendons, self.robot.stacked("length").astype(dtype))
            energy = energy + tendon_energy(self.tendons, lengths, rest, controls)
        if forces:
            f = jnp.stack([x.force for x in forces]).astype(dtype)
            energy = energy - jnp.sum(f * pos[force_start:])
        return energy

    def nonconservative_forces(self, q: Float[Array, " n_dofs"]) -> Float[Array, " n_dofs"] | None:
        """Generalised forces of follower forces and point moments (None when there are none)."""
        followers = self._of(PointForce, follower=True)
        moments = self._of(PointMoment)
        if not (followers or moments):
            return None
        items = followers + moments
        segs = np.asarray([x.segment for x in items])
        ss = jnp.concatenate([x.s.astype(q.dtype)[None] for x in items])
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
                moment = rot[k] @ moment
            cot_rot = cot_rot.at[k].set(moment_cotangent(moment, rot[k]))
        (generalised,) = pullback((cot_rot, cot_pos))
        return generalised

    def residual(self, q: Float[Array, " n_dofs"], controls) -> Float[Array, " n_dofs"]:
        """Equilibrium residual ``F(q) = grad V(q) - Q_nc(q)`` (generalised forces)."""
        force = jax.grad(self.potential_energy)(q, controls)
        extra = self.nonconservative_forces(q)
        return force if extra is None else force - extra

    # ----------------------------------------------------------------------------- conversion
    def zeros(self, dtype=float) -> Float[Array, " n_dofs"]:
        """The straight rest configuration."""
        return jnp.zeros(self.n_dofs, dtype)

    def default_controls(self, dtype=float) -> Float[Array, " m"]:
        return jnp.zeros(self.n_tendons, dtype)
