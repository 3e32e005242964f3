"""The robot body: segments in series, their stiffness, mass and shape, and the base."""

import abc

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

# Poisson's ratio of an incompressible elastomer: GJ = EI / (1 + nu) for a solid round section.
_POISSON_RATIO = 0.5
#: Default contraction limit of a segment, as a fraction of its rest length.
DEFAULT_CONTRACTION_LIMIT = 0.9


def as_float(x, name: str = "parameter") -> Array:
    """A parameter as a float array (float64 unless the value already is a float32 array).

    Raises a TypeError naming ``name`` for anything that is not real numbers (a string, None,
    a boolean, a complex number), instead of numpy's anonymous conversion error.
    """
    if isinstance(x, (jnp.ndarray, np.ndarray)):
        if jnp.issubdtype(x.dtype, jnp.floating):
            return jnp.asarray(x)
        if not (jnp.issubdtype(x.dtype, jnp.integer) and x.dtype != bool):
            raise TypeError(f"{name} must be real numbers, got an array of dtype {x.dtype}")
        return jnp.asarray(x, dtype=float)
    if isinstance(x, (bool, np.bool_)) or x is None or np.iscomplexobj(x):
        raise TypeError(f"{name} must be a real number, got {x!r}")
    try:
        arr = np.asarray(x)
    except (TypeError, ValueError) as err:  # ragged nesting
        raise TypeError(f"{name} must be a real number or an array of them, got {x!r}") from err
    if arr.dtype == bool or not (
        jnp.issubdtype(arr.dtype, jnp.floating) or jnp.issubdtype(arr.dtype, jnp.integer)
    ):
        raise TypeError(f"{name} must be a real number or an array of them, got {x!r}")
    return jnp.asarray(arr, dtype=float)


def float_field(name: str):
    """An ``eqx.field`` converter that makes a float array and names the field on bad input."""

    def convert(x):
        return as_float(x, name)

    return convert


def concrete(x) -> np.ndarray | None:
    """``x`` as a numpy array when its value is known now (not a tracer), else None."""
    try:
        return np.asarray(x, dtype=float)
    except Exception:  # a tracer inside jit / vmap: checks run before tracing instead
        return None


def known_sites(values, dtype):
    """Point sites ``s`` along segments: a numpy array when every one is known now, else a
    traced array. Known sites take the knot path of the kinematics (``Scene.frames``); a ``jnp``
    op inside ``jit`` would make even Python floats traced and send them down the grid path."""
    known = concrete(values)  # None when any of them is traced
    if known is not None and known.shape == (len(values),):
        return known
    return jnp.stack([jnp.asarray(v) for v in values]).astype(dtype)


def check_scalar(name: str, value) -> None:
    """Raise a ValueError naming ``name`` unless ``value`` is a single number."""
    if jnp.shape(value) != ():
        raise ValueError(f"{name} must be a single number, got shape {jnp.shape(value)}")


def check_positive(name: str, value, allow_zero: bool = False) -> None:
    """Raise a ValueError naming ``name`` unless every entry of ``value`` is finite and > 0."""
    v = concrete(value)
    if v is None:
        return
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {v}")
    if allow_zero and np.any(v < 0):
        raise ValueError(f"{name} must be >= 0, got {v}")
    if not allow_zero and np.any(v <= 0):
        raise ValueError(f"{name} must be > 0, got {v}")


def check_finite(name: str, value) -> None:
    v = concrete(value)
    if v is not None and not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {v}")


class StiffeningLaw(eqx.Module):
    """Bending stiffness multiplier as a differentiable function of the elongation ``dL``."""

    @abc.abstractmethod
    def __call__(self, elongation: Float[Array, ""], length: Float[Array, ""]) -> Float[Array, ""]:
        """Factor (> 0) on ``EI`` for elongation ``dL`` (m) of a segment of rest length (m)."""


class ExponentialStiffening(StiffeningLaw):
    """``EI(dL) = EI * exp(rate * (-dL / L))``: stiffer when contracted (``dL < 0``).

    Smooth and positive for any ``dL``; ``rate = ln(k) / f`` makes the segment ``k`` times
    stiffer at a contraction of a fraction ``f`` of its length.
    """

    rate: Float[Array, ""] = eqx.field(converter=float_field("ExponentialStiffening.rate"))

    def __check_init__(self):
        check_scalar("ExponentialStiffening.rate", self.rate)
        check_finite("ExponentialStiffening.rate", self.rate)

    def __call__(self, elongation, length):
        return jnp.exp(-self.rate * elongation / length)


class Segment(eqx.Module):
    """One segment of the robot. SI units.

    Args:
        length: rest length ``L`` (m).
        bending_stiffness: ``EI`` (N m^2) at the segment's base; the elastic energy uses
            ``k_b = EI / L`` on curvatures per unit ``s``.
        axial_stiffness: ``k_a`` (N/m) on the elongation ``dL``.
        torsion_stiffness: ``GJ`` (N m^2); default ``EI / (1 + nu)`` with ``nu = 0.5`` (solid
            round section of an incompressible elastomer). PAC's ``k_phi`` is ``GJ / L``.
        linear_density: mass per unit rest length (kg/m) at the base.
        radius: outer radius (m) at the base (for plots, and the taper).
        radius_tip: radius (m) at the tip for a tapered segment; then ``EI(s)`` scales with
            ``r(s)^4`` and the density with ``r(s)^2``, ``r`` linear in ``s``. None: uniform.
        stiffening: a :class:`StiffeningLaw` for ``EI`` against contraction; None: constant.
        contraction_limit: the largest contraction ``-dL`` (m) the segment can reach, ``0 <
            contraction_limit < length``: a modelled end stop (the coils or rings touching),
            see :func:`pacjax._model.energy.contraction_stop_energy`. None: 90 % of the length
            (a segment never reaches zero length, where a tendon's length has no derivative).
    """

    length: Float[Array, ""] = eqx.field(converter=float_field("Segment.length"))
    bending_stiffness: Float[Array, ""] = eqx.field(
        converter=float_field("Segment.bending_stiffness")
    )
    axial_stiffness: Float[Array, ""] = eqx.field(converter=float_field("Segment.axial_stiffness"))
    torsion_stiffness: Float[Array, ""] = eqx.field(
        converter=float_field("Segment.torsion_stiffness"), default=None
    )
    linear_density: Float[Array, ""] = eqx.field(
        converter=float_field("Segment.linear_density"), default=0.0
    )
    radius: Float[Array, ""] = eqx.field(converter=float_field("Segment.radius"), default=0.0)
    radius_tip: Float[Array, ""] | None = None
    stiffening: StiffeningLaw | None = None
    contraction_limit: Float[Array, ""] = eqx.field(
        converter=float_field("Segment.contraction_limit"), default=None
    )

    def __init__(
        self,
        length,
        bending_stiffness,
        axial_stiffness,
        torsion_stiffness=None,
        linear_density=0.0,
        radius=0.0,
        radius_tip=None,
        stiffening=None,
        contraction_limit=None,
    ):
        self.length = length
        self.bending_stiffness = bending_stiffness
        self.axial_stiffness = axial_stiffness
        if torsion_stiffness is None:
            torsion_stiffness = as_float(bending_stiffness, "Segment.bending_stiffness") / (
                1.0 + _POISSON_RATIO
            )
        self.torsion_stiffness = torsion_stiffness
        self.linear_density = linear_density
        self.radius = radius
        if radius_tip is not None:
            radius_tip = as_float(radius_tip, "Segment.radius_tip")
        self.radius_tip = radius_tip
        self.stiffening = stiffening
        if contraction_limit is None:
            contraction_limit = DEFAULT_CONTRACTION_LIMIT * as_float(length, "Segment.length")
        self.contraction_limit = contraction_limit

    def __check_init__(self):
        for field in (
            "length",
            "bending_stiffness",
            "axial_stiffness",
            "torsion_stiffness",
            "linear_density",
            "radius",
            "contraction_limit",
        ):
            check_scalar(f"Segment.{field}", getattr(self, field))
        if self.radius_tip is not None:
            check_scalar("Segment.radius_tip", self.radius_tip)
        check_positive("Segment.length", self.length)
        check_positive("Segment.bending_stiffness", self.bending_stiffness)
        check_positive("Segment.axial_stiffness", self.axial_stiffness)
        check_positive("Segment.torsion_stiffness", self.torsion_stiffness)
        check_positive("Segment.linear_density", self.linear_density, allow_zero=True)
        check_positive("Segment.radius", self.radius, allow_zero=True)
        if self.radius_tip is not None:
            check_positive("Segment.radius_tip", self.radius_tip)
            check_positive("Segment.radius (needed by radius_tip)", self.radius)
        check_positive("Segment.contraction_limit", self.contraction_limit)
        limit, length = concrete(self.contraction_limit), concrete(self.length)
        if limit is not None and length is not None and limit >= length:
            raise ValueError(
                f"Segment.contraction_limit must be below Segment.length ({float(length)} m), "
                f"got {float(limit)} m: a segment cannot contract to zero length"
            )
        if self.stiffening is not None and not isinstance(self.stiffening, StiffeningLaw):
            raise TypeError(f"Segment.stiffening must be a StiffeningLaw, got {self.stiffening!r}")

    def radius_at(self, s: Float[Array, "*n"]) -> Float[Array, "*n"]:
        """Outer radius (m) at ``s``."""
        if self.radius_tip is None:
            return self.radius * jnp.ones_like(s)
        return self.radius + (self.radius_tip - self.radius) * s

    def section_scale(self, s: Float[Array, "*n"]) -> Float[Array, "*n"] | None:
        """``r(s) / r(0)`` for a tapered segment, None for a uniform one."""
        if self.radius_tip is None:
            return None
        return self.radius_at(s) / self.radius


class Robot(eqx.Module):
    """Segments in series, clamped at a base frame.

    Args:
        segments: the segments from base (index 0) to tip.
        base_rotation: (3, 3) rotation from the base frame to the world frame (default
            identity: the robot's rest axis is the world's +z). A robot mounted horizontally or
            hanging down is a base rotation; gravity and world forces stay in the world frame.
        base_position: (3,) position (m) of the base in the world.
    """

    segments: tuple[Segment, ...]
    base_rotation: Float[Array, "3 3"] = eqx.field(converter=float_field("Robot.base_rotation"))
    base_position: Float[Array, "3"] = eqx.field(converter=float_field("Robot.base_position"))

    def __init__(self, segments, base_rotation=None, base_position=None):
        try:
            if isinstance(segments, Segment):
                raise TypeError
            self.segments = tuple(segments)
        except TypeError:
            raise TypeError(
                f"Robot.segments must be a sequence of Segments, got {type(segments).__name__}"
            ) from None
        self.base_rotation = np.eye(3) if base_rotation is None else base_rotation
        self.base_position = np.zeros(3) if base_position is None else base_position

    def __check_init__(self):
        if len(self.segments) == 0:
            raise ValueError("Robot.segments must hold at least one Segment")
        for i, seg in enumerate(self.segments):
            if not isinstance(seg, Segment):
                raise TypeError(f"Robot.segments[{i}] must be a Segment, got {type(seg).__name__}")
        if self.base_rotation.shape != (3, 3):
            raise ValueError(
                f"Robot.base_rotation must have shape (3, 3), got {self.base_rotation.shape}"
            )
        if self.base_position.shape != (3,):
            raise ValueError(
                f"Robot.base_position must have shape (3,), got {self.base_position.shape}"
            )
        r = concrete(self.base_rotation)
        if r is not None and (
            not np.all(np.isfinite(r))
            or not np.allclose(r.T @ r, np.eye(3), atol=1e-6)
            or np.linalg.det(r) < 0
        ):
            raise ValueError(
                "Robot.base_rotation must be a proper rotation matrix (R^T R = I, det 1)"
            )
        check_finite("Robot.base_position", self.base_position)

    @property
    def n_segments(self) -> int:
        return len(self.segments)

    def stacked(self, name: str) -> Float[Array, " n"]:
        """One per-segment parameter stacked over segments."""
        return jnp.stack([getattr(seg, name) for seg in self.segments])

    @property
    def total_length(self) -> Float[Array, ""]:
        return sum(seg.length for seg in self.segments)
