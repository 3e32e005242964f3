"""Rayleigh damping of the body and derivative gains of the tendon motors (:class:`Damping`)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import MATMUL_PRECISION
from .._jit import jit
from .._model.inertia import mass_matrix
from .._model.inputs import solver_dtype
from .._model.query import astype
from .._model.scene import Scene
from .._model.values import as_float, check_positive, concrete

#: Damping ratio of the lowest mode of the straight body under the default damping.
DEFAULT_DAMPING_RATIO = 0.05


class Damping(eqx.Module):
    """Rayleigh damping of the body and derivative gains of the tendon motors.

    ``D(q) = mass * M(q) + stiffness * K(q)``, ``K(q) = J(q)^T K_s J(q)`` the section stiffness
    ``K_s`` pulled back by the strain Jacobian ``J`` (the damping of a Kelvin-Voigt material,
    :func:`pacjax._model.energy.segment_strain_rate_energy`). At the straight rest configuration it
    is ``K_0``, the Hessian of the elastic energy. It damps every motion that strains the
    material, whatever the coordinates: a constant ``K_0`` left the bending-plane angle of a
    bent PCC/PAC segment (a swing across its bending plane) undamped, since that angle has no
    strain at ``q = 0``.

    Args:
        mass: ``alpha`` (1/s), mass-proportional coefficient.
        stiffness: ``beta`` (s), stiffness-proportional coefficient (damping ratio
            ``beta omega / 2`` for a mode of angular frequency ``omega``).
        tendon: ``kappa_D`` (N s/m) of the motors, one per tendon or one for all; None:
            ``beta kappa_P`` (the tendon springs damped like the body).

    ``Damping()`` is no damping at all (energy is conserved); :meth:`modal` picks ``beta`` for
    a damping ratio.
    """

    mass: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    stiffness: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    tendon: Float[Array, "*m"] | None = None

    def __init__(self, mass=0.0, stiffness=0.0, tendon=None):
        self.mass = mass
        self.stiffness = stiffness
        self.tendon = None if tendon is None else as_float(tendon)

    def __check_init__(self):
        for name in ("mass", "stiffness"):
            value = getattr(self, name)
            if jnp.shape(value) != ():
                raise ValueError(f"Damping.{name} must be a single number, got {jnp.shape(value)}")
            check_positive(f"Damping.{name}", value, allow_zero=True)
        if self.tendon is not None:
            if jnp.ndim(self.tendon) > 1:
                raise ValueError("Damping.tendon must be a number or one number per tendon")
            check_positive("Damping.tendon", self.tendon, allow_zero=True)

    @classmethod
    def modal(cls, scene: Scene, ratio: float = DEFAULT_DAMPING_RATIO, **kwargs) -> "Damping":
        """Stiffness-proportional damping with damping ratio ``ratio`` on the lowest mode of
        the straight robot at rest (elasticity and inertia only)."""
        if not (np.isfinite(ratio) and ratio >= 0):
            raise ValueError(f"ratio must be a finite number >= 0, got {ratio}")
        dtype = solver_dtype(scene)
        eigenvalues = _rest_eigenvalues(scene, dtype)
        _check_rest_modes(scene, dtype, concrete(eigenvalues))
        return cls(stiffness=2.0 * ratio / jnp.sqrt(jnp.min(eigenvalues)), **kwargs)

    def tendon_gains(self, scene: Scene, dtype) -> Float[Array, " m"]:
        """``kappa_D`` (N s/m) per tendon (tension-mode tendons ignore theirs)."""
        if self.tendon is not None:
            return jnp.broadcast_to(self.tendon.astype(dtype), (scene.n_tendons,))
        gains = [t.gain if t.mode == "length" else jnp.zeros(()) for t in scene.tendons]
        return self.stiffness.astype(dtype) * jnp.stack(gains).astype(dtype)


#: Relative error of a rest mode's eigenvalue, against float64's, beyond which a lower precision
#: does not resolve the mass matrix.
MODE_TOLERANCE = 0.1


def _check_rest_modes(scene: Scene, dtype, eigenvalues) -> None:
    """Refuse a mass matrix singular in this precision (``eigenvalues``: the rest modes'
    squared frequencies, None where traced), naming the cause, not "Damping.stiffness must be
    finite".

    Below float64 the modes are compared with float64's: where float64 resolves them and this
    precision's are not positive or more than :data:`MODE_TOLERANCE` off, the precision is the
    cause (the mass matrix of three 0.1 m ``PolynomialCurvature(3)`` segments is conditioned at
    2e11, past float32's rounding; whether its float32 Cholesky factor exists is up to the
    rounding, and a simulation of the wrong fast modes creeps at tiny steps). Otherwise a mode
    that is not positive names the lightest segment (a density of 1e-308 kg/m passes the > 0
    check)."""
    if eigenvalues is None:
        return
    lowest = float(np.min(eigenvalues))
    resolved = bool(np.isfinite(lowest) and lowest > 0)
    omega = np.sqrt(lowest) if resolved else np.nan  # rad/s
    if jnp.dtype(dtype) != jnp.float64:
        wide = concrete(_rest_eigenvalues(astype(scene, jnp.float64), jnp.float64))
        if wide is not None and np.all(np.isfinite(wide)) and np.all(wide > 0):
            error = float(np.max(np.abs(eigenvalues - wide) / wide))
            if not (resolved and error <= MODE_TOLERANCE):
                raise ValueError(
                    f"the mass matrix of the robot is singular in {jnp.dtype(dtype).name} "
                    f"(lowest mode {omega}, "
                    f"{np.sqrt(np.min(wide)):.4g} rad/s in float64; its rest modes up to "
                    f"{error:.0%} off): simulate this scene in float64, "
                    "pj.astype(scene, jnp.float64)"
                )
            return
    if not resolved:
        lightest = min(float(seg.linear_density) for seg in scene.robot.segments)
        raise ValueError(
            "the mass matrix of the robot is singular in this precision (lowest mode "
            f"{omega}): a segment's linear_density "
            f"({lightest:g} kg/m) is too small to simulate dynamics"
        )


@jit(once=True)  # run once per scene (pacjax._jit)
def _rest_eigenvalues(scene: Scene, dtype):
    q = scene.zeros(dtype)
    stiffness = jax.hessian(scene.elastic_energy)(q)
    return generalised_eigenvalues(stiffness, mass_matrix(scene, q))


def generalised_eigenvalues(stiffness, mass):
    """Eigenvalues of ``M^-1 K`` for symmetric ``K`` and positive definite ``M``."""
    chol = jnp.linalg.cholesky(mass)
    inv = jax.scipy.linalg.solve_triangular(
        chol, jnp.eye(mass.shape[0], dtype=mass.dtype), lower=True
    )
    return jnp.linalg.eigvalsh(
        jnp.matmul(
            jnp.matmul(inv, 0.5 * (stiffness + stiffness.T), precision=MATMUL_PRECISION),
            inv.T,
            precision=MATMUL_PRECISION,
        )
    )
