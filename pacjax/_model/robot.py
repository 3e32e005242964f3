"""The robot body: segments in series, their stiffness, mass and shape, and the base."""

import abc

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .. import _deprecated
from .values import as_float, check_finite, check_positive, check_scalar, concrete, float_field

# Poisson's ratio of an incompressible elastomer: GJ = EI / (1 + nu) for a solid round section.
_POISSON_RATIO = 0.5
#: Default contraction limit of a segment, as a fraction of its rest length.
DEFAULT_CONTRACTION_LIMIT = 0.9


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


class SectionProfile(eqx.Module):
    """A section that varies along a segment in a way no taper describes: ``EI(s)`` (and
    ``GJ(s)``) and ``rho A(s)`` as polynomials in the normalised arc length ``s``, as factors on
    the segment's base values (``bending_stiffness``, ``torsion_stiffness``,
    ``linear_density``), so the first coefficient is 1.

    They enter the elastic energy exactly (Gauss-Legendre of enough points: the scene checks) and
    the weight and inertia exactly up to degree 7. The elongation coordinate's stiffness stays
    ``Segment.axial_stiffness``: :meth:`end_load_stiffness` computes it from an ``EA(s)``
    profile.

    Args:
        bending: coefficients ``[1, b1, b2, ...]`` of ``EI(s) / EI(0)``, lowest first.
        density: coefficients ``[1, d1, ...]`` of ``rho A(s) / rho A(0)`` (default uniform).
    """

    bending: Float[Array, " k"] = eqx.field(converter=float_field("SectionProfile.bending"))
    density: Float[Array, " j"] = eqx.field(
        converter=float_field("SectionProfile.density"), default=(1.0,)
    )

    def __check_init__(self):
        for name in ("bending", "density"):
            value = getattr(self, name)
            if value.ndim != 1 or value.shape[0] < 1:
                raise ValueError(f"SectionProfile.{name} must be a list of coefficients")
            check_finite(f"SectionProfile.{name}", value)
            known = concrete(value)
            if known is None:
                continue
            if known[0] != 1.0:
                raise ValueError(
                    f"SectionProfile.{name}[0] must be 1 (a factor on the base value), got "
                    f"{known[0]}"
                )
            if np.any(np.polynomial.polynomial.polyval(np.linspace(0, 1, 201), known) <= 0):
                raise ValueError(f"SectionProfile.{name} must stay > 0 for s in [0, 1]")

    @staticmethod
    def _polyval(coefficients, s):
        out = jnp.zeros_like(s) + coefficients[-1]
        for c in coefficients[-2::-1]:
            out = out * s + c
        return out

    def bending_at(self, s: Float[Array, "*n"]) -> Float[Array, "*n"]:
        return self._polyval(self.bending, s)

    def density_at(self, s: Float[Array, "*n"]) -> Float[Array, "*n"]:
        return self._polyval(self.density, s)

    @property
    def degree(self) -> int:
        """The bending polynomial's degree (the elastic energy's quadrature needs it)."""
        return self.bending.shape[0] - 1

    @staticmethod
    def end_load_stiffness(axial_rigidity, length, coefficients) -> Float[Array, ""]:
        """``k_a = 1 / int_0^L dx / EA(x)`` (N/m) for ``EA(s) = axial_rigidity * p(s)``, ``p``
        the polynomial ``coefficients`` (32-point Gauss-Legendre: converged to round-off for a
        ``p`` that stays well away from zero on ``[0, 1]``)."""
        nodes, weights = np.polynomial.legendre.leggauss(32)
        s = 0.5 * (nodes + 1.0)
        p = SectionProfile._polyval(as_float(coefficients, "coefficients"), jnp.asarray(s))
        return axial_rigidity / (length * jnp.sum(0.5 * weights / p))


class Segment(eqx.Module):
    """One segment of the robot. SI units.

    The stiffness fields are what a user who measured them enters;
    :meth:`Segment.from_material` derives them from a material and a circular section.

    Args:
        length: rest length ``L`` (m).
        bending_stiffness: ``EI`` (N m^2) at the segment's base; the elastic energy uses
            ``k_b = EI / L`` on curvatures per unit ``s``.
        axial_stiffness: ``k_a`` (N/m) on the elongation ``dL``.
        torsion_stiffness: ``GJ`` (N m^2); default ``EI / (1 + nu)`` with ``nu = 0.5`` (solid
            round section of an incompressible elastomer). PAC's ``k_phi`` is ``GJ / L``.
        linear_density: mass per unit rest length (kg/m) at the base.
        radius: outer radius (m) at the base (for plots, and the taper).
        radius_tip: outer radius (m) at the tip for a tapered segment. Along a taper ``EI(s)``
            and ``GJ(s)`` scale with the section's second moment ``r_o(s)^4 - r_i(s)^4`` and the
            density with its area ``r_o(s)^2 - r_i(s)^2``, both radii linear in ``s``. None:
            the outer radius is uniform.
        inner_radius: inner radius (m) of a hollow section at the base (default 0: solid).
        inner_radius_tip: inner radius (m) at the tip (None: that of the base).
        stiffening: a :class:`StiffeningLaw` for ``EI`` against contraction; None: constant.
        contraction_limit: the largest contraction ``-dL`` (m) the segment can reach, ``0 <
            contraction_limit < length``: a modelled end stop (the coils or rings touching),
            see :func:`pacjax._model.energy.contraction_stop_energy`. None: 90 % of the length
            (a segment never reaches zero length, where a tendon's length has no derivative).
        rest_curvature: the strain coordinates of the unloaded segment, in its strain model's
            own form and order without ``dL`` (PCC ``[c0, phi]``, PAC ``[c0, c1, phi]``,
            ``PolynomialCurvature`` its coefficients), curvatures in rad per unit ``s`` (``L``
            times 1/m). The elastic energy is measured from this shape. None: straight.
        extensible: False removes the elongation ``dL`` from the coordinates (the segment
            keeps its length; ``axial_stiffness`` is then unused).
        profile: a :class:`SectionProfile` (measured ``EI(s)``, ``rho A(s)``) instead of a
            taper. None: uniform, or the taper.
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
    inner_radius: Float[Array, ""] = eqx.field(
        converter=float_field("Segment.inner_radius"), default=0.0
    )
    inner_radius_tip: Float[Array, ""] | None = None
    rest_curvature: Float[Array, " c"] | None = None
    extensible: bool = eqx.field(static=True, default=True)
    profile: SectionProfile | None = None

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
        inner_radius=0.0,
        inner_radius_tip=None,
        rest_curvature=None,
        extensible=True,
        profile=None,
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
        self.inner_radius = inner_radius
        if inner_radius_tip is not None:
            inner_radius_tip = as_float(inner_radius_tip, "Segment.inner_radius_tip")
        self.inner_radius_tip = inner_radius_tip
        if rest_curvature is not None:
            rest_curvature = as_float(rest_curvature, "Segment.rest_curvature")
        self.rest_curvature = rest_curvature
        if not isinstance(extensible, (bool, np.bool_)):
            raise TypeError(f"Segment.extensible must be True or False, got {extensible!r}")
        self.extensible = bool(extensible)
        self.profile = profile

    @classmethod
    def from_material(
        cls,
        length,
        *,
        young_modulus,
        radius,
        density=0.0,
        poisson=_POISSON_RATIO,
        radius_tip=None,
        inner_radius=0.0,
        inner_radius_tip=None,
        **kwargs,
    ) -> "Segment":
        """A segment of one material with a solid or hollow circular section, linearly tapered
        when a tip radius is given.

        ``EI = E pi (r_o^4 - r_i^4) / 4`` and ``rho A = rho pi (r_o^2 - r_i^2)`` at the base,
        varying along the taper as :class:`Segment` describes; ``GJ = E / (2 (1 + nu)) J`` with
        ``J = 2 I``. The single elongation coordinate stretches the segment uniformly; its
        stiffness is the end-load stiffness ``k_a = 1 / int_0^L dx / (E A(x))`` (``E pi r_0 r_1
        / L`` for a solid linear taper), which is also the least axial energy of any strain
        distribution along the segment with that total elongation, so it is exact wherever the
        axial force is uniform along the segment (no distributed axial load in it). Written
        with ``jnp``, so every value stays differentiable in the material parameters (fitting
        ``E`` or ``rho``).

        Args:
            length: rest length ``L`` (m).
            young_modulus: ``E`` (Pa).
            radius: outer radius (m) at the base.
            density: mass density ``rho`` (kg/m^3).
            poisson: Poisson's ratio ``nu`` (default 0.5, an incompressible elastomer).
            radius_tip, inner_radius, inner_radius_tip: see :class:`Segment`.
            **kwargs: the other :class:`Segment` arguments (``stiffening``,
                ``contraction_limit``, ``rest_curvature``, ``extensible``).
        """
        for name, value in (("young_modulus", young_modulus), ("radius", radius)):
            check_scalar(f"Segment.from_material {name}", as_float(value, name))
            check_positive(f"Segment.from_material {name}", as_float(value, name))
        check_positive("Segment.from_material density", as_float(density, "density"), True)
        nu = concrete(as_float(poisson, "poisson"))
        if nu is not None and not -1.0 < float(nu) <= 0.5:
            raise ValueError(f"Segment.from_material poisson must lie in (-1, 0.5], got {nu}")
        e = as_float(young_modulus, "young_modulus")
        r0 = as_float(radius, "radius")
        r1 = r0 if radius_tip is None else as_float(radius_tip, "radius_tip")
        i0 = as_float(inner_radius, "inner_radius")
        i1 = i0 if inner_radius_tip is None else as_float(inner_radius_tip, "inner_radius_tip")
        _check_section("Segment.from_material", r0, r1, i0, i1)
        second_moment, area = circular_section(r0, i0)
        bending = e * second_moment
        # A(s) = pi (r_o + r_i)(r_o - r_i), each factor linear in s: int_0^1 ds / A in closed
        # form (d/ds log(f / g) = (f' g - f g') / (f g), and f' g - f g' is constant).
        f0, f1, g0, g1 = r0 + i0, r1 + i1, r0 - i0, r1 - i1
        det = (f1 - f0) * g0 - f0 * (g1 - g0)
        x = det / (f0 * g1)
        small = jnp.abs(x) < 1e-6
        x_safe = jnp.where(small, 1.0, x)
        log_ratio = jnp.where(small, 1.0 - x / 2.0 + x * x / 3.0, jnp.log1p(x_safe) / x_safe)
        inverse_area = log_ratio / (jnp.pi * f0 * g1)
        return cls(
            length=length,
            bending_stiffness=bending,
            axial_stiffness=e / (as_float(length, "Segment.length") * inverse_area),
            torsion_stiffness=bending / (1.0 + as_float(poisson, "poisson")),
            linear_density=as_float(density, "density") * area,
            radius=r0,
            radius_tip=radius_tip,
            inner_radius=inner_radius,
            inner_radius_tip=inner_radius_tip,
            **kwargs,
        )

    def __check_init__(self):
        for field in (
            "length",
            "bending_stiffness",
            "axial_stiffness",
            "torsion_stiffness",
            "linear_density",
            "radius",
            "contraction_limit",
            "inner_radius",
        ):
            check_scalar(f"Segment.{field}", getattr(self, field))
        for field in ("radius_tip", "inner_radius_tip"):
            if getattr(self, field) is not None:
                check_scalar(f"Segment.{field}", getattr(self, field))
        check_positive("Segment.length", self.length)
        check_positive("Segment.bending_stiffness", self.bending_stiffness)
        check_positive("Segment.axial_stiffness", self.axial_stiffness)
        check_positive("Segment.torsion_stiffness", self.torsion_stiffness)
        check_positive("Segment.linear_density", self.linear_density, allow_zero=True)
        check_positive("Segment.radius", self.radius, allow_zero=True)
        check_positive("Segment.inner_radius", self.inner_radius, allow_zero=True)
        if self.radius_tip is not None:
            check_positive("Segment.radius_tip", self.radius_tip)
            check_positive("Segment.radius (needed by radius_tip)", self.radius)
        if self.inner_radius_tip is not None:
            check_positive("Segment.inner_radius_tip", self.inner_radius_tip, allow_zero=True)
        inner = concrete(self.inner_radius)
        if self.tapered or inner is None or inner > 0:
            _check_section(
                "Segment",
                self.radius,
                self.radius_at(np.ones(())),
                self.inner_radius,
                self.inner_radius_at(np.ones(())),
            )
        if self.rest_curvature is not None:
            if self.rest_curvature.ndim != 1:
                raise ValueError(
                    "Segment.rest_curvature must be a 1-d array (the model's strain "
                    f"coordinates), got shape {self.rest_curvature.shape}"
                )
            check_finite("Segment.rest_curvature", self.rest_curvature)
        check_positive("Segment.contraction_limit", self.contraction_limit)
        limit, length = concrete(self.contraction_limit), concrete(self.length)
        if limit is not None and length is not None and limit >= length:
            raise ValueError(
                f"Segment.contraction_limit must be below Segment.length ({float(length)} m), "
                f"got {float(limit)} m: a segment cannot contract to zero length"
            )
        if self.profile is not None:
            if not isinstance(self.profile, SectionProfile):
                raise TypeError(f"Segment.profile must be a SectionProfile, got {self.profile!r}")
            if self.tapered:
                raise ValueError(
                    "Segment.profile replaces the taper: give either radius_tip / "
                    "inner_radius_tip or a profile"
                )
        if self.stiffening is not None and not isinstance(self.stiffening, StiffeningLaw):
            raise TypeError(f"Segment.stiffening must be a StiffeningLaw, got {self.stiffening!r}")

    def base_section(self) -> tuple[Float[Array, ""], Float[Array, ""]]:
        """:func:`circular_section` at the base (from ``radius`` and ``inner_radius``)."""
        return circular_section(self.radius, self.inner_radius)

    @property
    def tapered(self) -> bool:
        """Whether the section varies along the segment."""
        return self.radius_tip is not None or self.inner_radius_tip is not None

    def radius_at(self, s: Float[Array, "*n"]) -> Float[Array, "*n"]:
        """Outer radius (m) at ``s``."""
        if self.radius_tip is None:
            return self.radius * jnp.ones_like(s)
        return self.radius + (self.radius_tip - self.radius) * s

    def inner_radius_at(self, s: Float[Array, "*n"]) -> Float[Array, "*n"]:
        """Inner radius (m) at ``s`` (0 for a solid section)."""
        if self.inner_radius_tip is None:
            return self.inner_radius * jnp.ones_like(s)
        return self.inner_radius + (self.inner_radius_tip - self.inner_radius) * s

    def _section_ratio(self, s, power: int):
        outer, inner = self.radius_at(s), self.inner_radius_at(s)
        base = self.radius**power - self.inner_radius**power
        return (outer**power - inner**power) / base

    def bending_profile(self, s: Float[Array, "*n"]) -> Float[Array, "*n"] | None:
        """``EI(s) / EI(0)`` (and ``GJ``'s) of a tapered or profiled segment, None for a
        uniform one."""
        if self.profile is not None:
            return self.profile.bending_at(s)
        return self._section_ratio(s, 4) if self.tapered else None

    def area_profile(self, s: Float[Array, "*n"]) -> Float[Array, "*n"] | None:
        """``rho A(s) / rho A(0)`` of a tapered or profiled segment, None for a uniform one."""
        if self.profile is not None:
            return self.profile.density_at(s)
        return self._section_ratio(s, 2) if self.tapered else None

    def section_scale(self, s: Float[Array, "*n"]) -> Float[Array, "*n"] | None:
        """Deprecated: ``r(s) / r(0)`` of the outer radius (use :meth:`bending_profile` and
        :meth:`area_profile`, which also hold a hollow section or a profile)."""
        _deprecated.warn("Segment.section_scale", "Segment.bending_profile / area_profile")
        if self.radius_tip is None:
            return None
        return self.radius_at(s) / self.radius

    def profile_degree(self) -> int:
        """Polynomial degree in ``s`` of :meth:`bending_profile` (0 when uniform)."""
        if self.profile is not None:
            return self.profile.degree
        return 4 if self.tapered else 0


def circular_section(outer, inner) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """``(I, A)``: second moment of area (m^4) and area (m^2) of a solid (``inner = 0``) or
    hollow circle."""
    return 0.25 * jnp.pi * (outer**4 - inner**4), jnp.pi * (outer**2 - inner**2)


def _check_section(owner: str, r0, r1, i0, i1) -> None:
    """Raise a ValueError naming ``owner`` unless the inner radius stays below the outer one at
    both ends (values known now; traced ones are not checked)."""
    known = [concrete(x) for x in (r0, r1, i0, i1)]
    if any(x is None for x in known):
        return
    r0, r1, i0, i1 = (float(x) for x in known)
    if r0 <= 0 or r1 <= 0:
        raise ValueError(f"{owner}: a hollow or tapered section needs radius > 0 at both ends")
    if i0 < 0 or i1 < 0 or i0 >= r0 or i1 >= r1:
        raise ValueError(
            f"{owner}: inner_radius must lie in [0, radius) at both ends, got inner "
            f"{i0:g} -> {i1:g} m inside outer {r0:g} -> {r1:g} m"
        )


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
