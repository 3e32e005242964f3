"""External loads: gravity, point masses, point forces and point moments.

World-fixed forces and gravity are conservative and enter the potential energy. Follower forces
(given in the local cross-section frame, so they turn with the body) and point moments are
generalised forces that enter the equilibrium residual directly (a world-fixed moment is not
conservative on SO(3) in general).
"""

import equinox as eqx
import numpy as np
from jaxtyping import Array, Float

from .values import check_finite, check_positive, check_scalar, concrete, float_field


def _check_site(owner: str, segment, s) -> None:
    if not isinstance(segment, (int, np.integer)) or isinstance(segment, bool) or segment < 0:
        raise ValueError(f"{owner}.segment must be an integer index >= 0, got {segment!r}")
    check_scalar(f"{owner}.s", s)
    v = concrete(s)
    if v is not None and not (np.isfinite(v) and 0.0 <= v <= 1.0):
        raise ValueError(f"{owner}.s must lie in [0, 1], got {s}")


def _check_flag(name: str, value) -> None:
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {value!r}")


def _check_vector(name: str, v) -> None:
    if v.shape != (3,):
        raise ValueError(f"{name} must have shape (3,), got {v.shape}")
    check_finite(name, v)


class Gravity(eqx.Module):
    """Uniform gravity: acceleration ``g`` (m/s^2) along the unit ``direction`` (world frame)."""

    g: Float[Array, ""] = eqx.field(converter=float_field("Gravity.g"), default=9.81)
    direction: Float[Array, "3"] = eqx.field(
        converter=float_field("Gravity.direction"), default=(0.0, 0.0, -1.0)
    )

    def __check_init__(self):
        check_scalar("Gravity.g", self.g)
        check_positive("Gravity.g", self.g, allow_zero=True)
        _check_vector("Gravity.direction", self.direction)
        d = concrete(self.direction)
        if d is not None and not np.isclose(np.linalg.norm(d), 1.0, atol=1e-6):
            raise ValueError(f"Gravity.direction must be a unit vector, got {d}")

    @property
    def acceleration(self) -> Float[Array, "3"]:
        return self.g * self.direction


class PointMass(eqx.Module):
    """A mass (kg) attached at ``(segment, s)``, e.g. a tip payload or an end ring."""

    mass: Float[Array, ""] = eqx.field(converter=float_field("PointMass.mass"))
    segment: int = eqx.field(static=True)
    s: Float[Array, ""] = eqx.field(converter=float_field("PointMass.s"), default=1.0)

    def __check_init__(self):
        check_scalar("PointMass.mass", self.mass)
        check_positive("PointMass.mass", self.mass, allow_zero=True)
        _check_site("PointMass", self.segment, self.s)


class PointForce(eqx.Module):
    """A force (N) at ``(segment, s)``: in the world frame, or (``follower=True``) in the local
    cross-section frame so that it turns with the body (a load cell held perpendicular to the
    backbone is ``follower=True`` with a force along local x or y)."""

    force: Float[Array, "3"] = eqx.field(converter=float_field("PointForce.force"))
    segment: int = eqx.field(static=True)
    s: Float[Array, ""] = eqx.field(converter=float_field("PointForce.s"), default=1.0)
    follower: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        _check_vector("PointForce.force", self.force)
        _check_site("PointForce", self.segment, self.s)
        _check_flag("PointForce.follower", self.follower)


class PointMoment(eqx.Module):
    """A moment (N m) at ``(segment, s)``, in the world frame or (``follower=True``) local."""

    moment: Float[Array, "3"] = eqx.field(converter=float_field("PointMoment.moment"))
    segment: int = eqx.field(static=True)
    s: Float[Array, ""] = eqx.field(converter=float_field("PointMoment.s"), default=1.0)
    follower: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        _check_vector("PointMoment.moment", self.moment)
        _check_site("PointMoment", self.segment, self.s)
        _check_flag("PointMoment.follower", self.follower)


Load = Gravity | PointMass | PointForce | PointMoment
