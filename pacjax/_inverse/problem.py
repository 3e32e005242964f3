"""The inverse-statics least-squares problem: targets, command bounds and limits, the residual
(through the equilibrium, with implicit-function-theorem derivatives) and one compiled
Levenberg-Marquardt solve. The workflows (starts, batches, tracking) are in
:mod:`pacjax.inverse`."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

from .._config import MATMUL_PRECISION
from .._jit import jit
from .._model.rotation import matvec3
from .._model.scene import Scene
from .._model.sites import normalise_sites
from .._statics.equilibrium import linearised_equilibrium
from .._statics.options import SolverOptions

#: The residual is expressed in this unit (m) so that its Jacobian with respect to the latent
#: commands is of order one for robots of centimetre-to-decimetre size: Levenberg-Marquardt's
#: first damping (1) is then neither far too strong nor too weak.
_RESIDUAL_UNIT = 0.01

#: Residual (in ``_RESIDUAL_UNIT``) that replaces the error where the inner equilibrium solve
#: failed, so that the least-squares solver rejects the step instead of trusting it.
_FAILED_RESIDUAL = 1e3


# ------------------------------------------------------------------------------ the problem
class _Target(eqx.Module):
    """Target and weights in arrays (traced); which kind of target is static."""

    kind: str = eqx.field(static=True)  # "position" | "pose" | "markers"
    segments: tuple[int, ...] = eqx.field(static=True)
    s: Float[Array, " m"]
    offsets: Float[Array, "m 3"]
    points: Float[Array, "m 3"]  # NaN entries (missing markers) are replaced by 0 and masked
    mask: Float[Array, "m 3"]
    rotation: Float[Array, "3 3"]
    orientation_weight: Float[Array, ""]


class CommandLimits(eqx.Module):
    lower: Float[Array, " n_tendons"]
    upper: Float[Array, " n_tendons"]
    tension_weight: Float[Array, ""]
    max_tension: Float[Array, " n_tendons"] | None
    tension_limit_weight: Float[Array, ""]
    max_contraction: Float[Array, " n_segments"] | None  # m
    contraction_weight: Float[Array, ""]


def _commands(z, limits: CommandLimits):
    return limits.lower + (limits.upper - limits.lower) * jax.nn.sigmoid(z)


def _latent(u, limits: CommandLimits):
    """``z`` with ``_commands(z) = u``; commands on a bound start just inside it."""
    frac = (u - limits.lower) / (limits.upper - limits.lower)
    frac = jnp.clip(frac, 1e-3, 1.0 - 1e-3)
    return jnp.log(frac) - jnp.log1p(-frac)


def _sites_pose(scene: Scene, target: _Target, q):
    """Positions of the target's sites, and the tip frame."""
    segs = np.asarray(target.segments + (scene.n_segments - 1,))
    s = jnp.concatenate([target.s, jnp.ones(1, q.dtype)])
    rot, pos = scene.frames(q, segs, s)
    points = pos[:-1] + matvec3(rot[:-1], target.offsets)
    return points, pos[-1], rot[-1]


def _rotation_error(r_target, r):
    """Axis times sine of the rotation from ``r_target`` to ``r`` (smooth, 0 when equal)."""
    m = jnp.matmul(r_target.T, r, precision=MATMUL_PRECISION)
    return 0.5 * jnp.stack([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])


def _angle(r_target, r):
    m = jnp.matmul(r_target.T, r, precision=MATMUL_PRECISION)
    sin = jnp.linalg.norm(_rotation_error(r_target, r))
    cos = 0.5 * (jnp.trace(m) - 1.0)
    return jnp.arctan2(sin, cos)


def _errors(scene, target: _Target, q):
    """(position error (m), orientation error (rad), tip position, tip rotation)."""
    points, tip, rot = _sites_pose(scene, target, q)
    dist = jnp.sqrt(jnp.sum(((points - target.points) * target.mask) ** 2, axis=-1))
    angle = _angle(target.rotation, rot) if target.kind == "pose" else jnp.zeros((), q.dtype)
    return jnp.max(dist), angle, tip, rot


class _Residual(eqx.Module):
    """The least-squares residual (m) of the commands' latent ``z``; aux: ``(q, ok)``."""

    options: SolverOptions = eqx.field(static=True)

    def __call__(self, z, args):
        scene, target, limits, q0 = args
        return _residual(scene, target, limits, q0, z, self.options)


def _equilibrium(scene, u, q0, options):
    """Equilibrium ``q*(u)``, its derivative by the implicit function theorem with the
    continuation's last Jacobian (:mod:`pacjax._statics.implicit`, as every solve's): the
    Levenberg-Marquardt Jacobians differentiate it in forward mode, one dense solve per
    direction, never through the solver's iterations.

    Returns ``(q, ok)``; ``ok`` is False for a failed or unstable solve.
    """
    eq, _ = linearised_equilibrium(scene, u, q0, options)
    return eq.q, eq.converged & eq.stable


def _residual(scene, target, limits, q0, z, options):
    u = _commands(z, limits)
    q, ok = _equilibrium(scene, u, q0, options)
    points, _, rot = _sites_pose(scene, target, q)
    parts = [((points - target.points) * target.mask).reshape(-1)]
    if target.kind == "pose":
        parts.append(target.orientation_weight * _rotation_error(target.rotation, rot))
    if scene.n_tendons:
        tension = scene.tendon_tensions(q, u)
        parts.append(limits.tension_weight * tension)
        if limits.max_tension is not None:
            over = jnp.maximum(tension - limits.max_tension, 0.0)
            parts.append(limits.tension_limit_weight * over)
    if limits.max_contraction is not None:
        dl = scene.coordinates(q)[:, -1]
        parts.append(limits.contraction_weight * jnp.maximum(-dl - limits.max_contraction, 0.0))
    r = jnp.concatenate(parts) / _RESIDUAL_UNIT
    return jnp.where(ok, r, _FAILED_RESIDUAL), (q, ok)


class Solve(eqx.Module):
    """Where one Levenberg-Marquardt solve stopped (a leading batch axis from :func:`solve_many`).

    The solvers return JAX arrays; the batch workflow keeps NumPy copies and merges them row by
    row (the fields but ``iterations`` are replaced together, ``iterations`` add up).
    """

    #: (n_tendons,) commands where the solve stopped (m pull-in, or N tension).
    controls: Float[Array, "*batch n_tendons"]
    #: (n_dofs,) the equilibrium under ``controls``.
    q: Float[Array, "*batch n_dofs"]
    #: position error (m): tip, or the worst marker site; inf where ``converged`` is False.
    error: Float[Array, "*batch"]
    #: angle (rad) between the reached and the target tip orientation (0 but for poses).
    orientation_error: Float[Array, "*batch"]
    #: (3,) reached tip position (m).
    position: Float[Array, "*batch 3"]
    #: (3, 3) reached tip orientation.
    rotation: Float[Array, "*batch 3 3"]
    #: the equilibrium at ``controls`` converged and is stable.
    converged: Bool[Array, "*batch"]
    #: Levenberg-Marquardt iterations.
    iterations: Int[Array, "*batch"]


def _solve_core(scene, target, limits, u0, q0, rtol, atol, max_steps, options) -> Solve:
    """One Levenberg-Marquardt solve from ``u0`` (traceable, vmappable)."""
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    z0 = _latent(u0, limits)
    sol = optx.least_squares(
        _Residual(options),
        solver,
        z0,
        args=(scene, target, limits, q0),
        has_aux=True,
        max_steps=max_steps,
        throw=False,
    )
    u = _commands(sol.value, limits)
    q, ok = sol.aux
    error, angle, tip, rot = _errors(scene, target, q)
    error = jnp.where(ok, error, jnp.inf)
    return Solve(
        controls=u,
        q=q,
        error=error,
        orientation_error=angle,
        position=tip,
        rotation=rot,
        converged=ok,
        iterations=sol.stats["num_steps"],
    )


solve_one = jit(_solve_core)


@jit
def solve_many(scene, target, limits, u0, q0, rtol, atol, max_steps, options):
    def one(t, u, q):
        return _solve_core(scene, t, limits, u, q, rtol, atol, max_steps, options)

    return jax.vmap(one)(target, u0, q0)


@jit
def tensions_at(scene, q, u):
    return scene.tendon_tensions(q, u)


#: How far past the point where it turns taut a slack tendon is pulled (fraction of the command
#: range) when a solve stopped short of its target with that tendon slack.
_TAUT_MARGIN = 0.01


def _taut_core(scene, limits: CommandLimits, u, q):
    """Commands with every slack tendon pulled until it is just taut at ``q`` (within the
    bounds), and whether any command changed.

    A slack tendon's command does not move the equilibrium, so its column of the least-squares
    Jacobian is zero and Levenberg-Marquardt cannot see that pulling it would help; the
    low-tension preference leads tendons there. Restarting from these commands gives the
    solver that column back.
    """
    taut = scene.rest_tendon_lengths(q.dtype) - scene.tendon_lengths(q)
    taut = taut + _TAUT_MARGIN * (limits.upper - limits.lower)
    slack = scene.tendon_tensions(q, u) <= 0.0
    new = jnp.where(slack, jnp.clip(jnp.maximum(u, taut), limits.lower, limits.upper), u)
    return new, jnp.any(new != u)


taut_one = jit(_taut_core)


@jit
def taut_many(scene, limits, u, q):
    return jax.vmap(lambda a, b: _taut_core(scene, limits, a, b))(u, q)


# ------------------------------------------------------------------------------ input checks
def checked_array(name, value, shape=None):
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be numbers, got {value!r}") from None
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    return arr


def checked_finite(name, arr):
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite (no NaN or infinity)")
    return arr


def make_target(scene, target, rotation, orientation_weight, sites, batched=False):
    """A :class:`_Target` (with a leading batch axis when ``batched``).

    Checks, in this order: the target (a tip position, or one position per marker site), the
    rotation (pose targets), the orientation weight.
    """
    if sites is None:
        points, sites, kind = _tip_points(scene, target, rotation, batched)
    else:
        points, sites, kind = _marker_points(scene, target, rotation, sites, batched)
    n_batch = points.shape[0] if batched else None
    rot = _target_rotation(rotation, batched, n_batch)
    weight = float(orientation_weight)
    if not (np.isfinite(weight) and weight > 0):
        raise ValueError(f"orientation_weight must be > 0 (m per rad), got {orientation_weight}")
    mask = (~np.isnan(points)).astype(float)
    m = len(sites)

    def per_batch(x):
        return np.broadcast_to(x, ((n_batch,) if batched else ()) + np.shape(x))

    return _Target(
        kind=kind,
        segments=tuple(x[0] for x in sites),
        s=jnp.asarray(per_batch(np.asarray([x[1] for x in sites]))),
        offsets=jnp.asarray(per_batch(np.asarray([x[2] for x in sites]).reshape(m, 3))),
        points=jnp.asarray(np.nan_to_num(points)),
        mask=jnp.asarray(mask),
        rotation=jnp.asarray(rot),
        orientation_weight=jnp.asarray(per_batch(np.asarray(weight))),
    )


def _tip_points(scene, target, rotation, batched):
    """A tip target, checked: ``(points (..., 1, 3), the tip as the one site, kind)``."""
    arr = checked_array("target", target)
    ok = arr.shape == (3,) if not batched else (arr.ndim == 2 and arr.shape[1:] == (3,))
    if not ok or arr.size == 0:
        what = "(3,) (a tip position in m)" if not batched else "(n_targets, 3)"
        hint = "; pass sites= for marker targets" if arr.ndim >= 2 and not batched else ""
        raise ValueError(f"target must have shape {what}, got {arr.shape}{hint}")
    checked_finite("target", arr)
    lead = (-1,) if batched else ()
    points = arr.reshape(lead + (1, 3))
    sites = ((scene.n_segments - 1, 1.0, (0.0, 0.0, 0.0)),)
    return points, sites, "position" if rotation is None else "pose"


def _marker_points(scene, target, rotation, sites, batched):
    """A marker target, checked: ``(points (..., m, 3) with NaN for missing coordinates, the
    normalised sites, "markers")``."""
    sites = normalise_sites(sites, scene.n_segments, "sites")
    if not sites:
        raise ValueError("sites must hold at least one (segment, s) marker site")
    if rotation is not None:
        raise ValueError("rotation= applies to a tip target, not to marker sites")
    arr = checked_array("target", target)
    m = len(sites)
    if arr.shape[-2:] != (m, 3) or arr.ndim != (3 if batched else 2):
        want = f"({'n_targets, ' if batched else ''}{m}, 3)"
        raise ValueError(f"target must have shape {want} (one xyz per site), got {arr.shape}")
    if np.any(np.isinf(arr)):
        raise ValueError("target must not hold infinite values (NaN marks a missing marker)")
    if np.any(np.all(np.isnan(arr), axis=(-1, -2))):
        raise ValueError("every target needs at least one known marker position")
    return arr, sites, "markers"


def _target_rotation(rotation, batched, n_batch):
    """The target tip orientation, checked ((3, 3), or (n_batch, 3, 3) when ``batched``; one
    (3, 3) is shared by all targets); the identity for position and marker targets, whose
    orientation error is not part of the residual."""
    if rotation is None:
        return np.broadcast_to(np.eye(3), (n_batch, 3, 3) if batched else (3, 3))
    rot = checked_array("rotation", rotation)
    want = (3, 3) if not batched else (n_batch, 3, 3)
    if rot.shape == (3, 3) and batched:
        rot = np.broadcast_to(rot, want)
    if rot.shape != want:
        raise ValueError(f"rotation must have shape {want}, got {rot.shape}")
    checked_finite("rotation", rot)
    eye = np.broadcast_to(np.eye(3), rot.shape)
    if not np.allclose(np.swapaxes(rot, -1, -2) @ rot, eye, atol=1e-6) or np.any(
        np.linalg.det(rot) < 0
    ):
        raise ValueError("rotation must be a rotation matrix (orthonormal, det +1)")
    return rot


def default_command_range(scene: Scene, max_contraction: float = 0.5) -> tuple[np.ndarray, ...]:
    """Default ``(lower, upper)`` commands: a length-mode tendon from 0 (its rest length) to
    ``max_contraction`` times the length it spans (the segments from its entry ring to its
    anchor); ``nan`` for tension-mode tendons (no natural range: give ``upper``)."""
    lengths = np.asarray(scene.robot.stacked("length"), float)
    lower = np.zeros(scene.n_tendons)
    upper = np.full(scene.n_tendons, np.nan)
    for i, t in enumerate(scene.tendons):
        if t.mode == "length":
            start = t.segment if t.bowden else 0
            span = lengths[start : t.segment].sum() + t.s * lengths[t.segment]
            upper[i] = max_contraction * span
    return lower, upper


def _per_tendon(name, value, n):
    arr = checked_array(name, value)
    if arr.shape not in ((), (n,)):
        raise ValueError(
            f"{name} must be a number or have shape ({n},) (one per tendon), got {arr.shape}"
        )
    return np.broadcast_to(arr, (n,)).copy()


def make_limits(
    scene,
    lower,
    upper,
    max_tension,
    max_contraction,
    tension_weight,
    tension_limit_weight,
    contraction_weight,
):
    n = scene.n_tendons
    if n == 0:
        raise ValueError("the scene has no tendons: there is nothing to command")
    mc = float(max_contraction) if max_contraction is not None else None
    if mc is not None and not 0.0 < mc < 1.0:
        raise ValueError(
            f"max_contraction must lie in (0, 1) (fraction of L), got {max_contraction}"
        )
    d_lower, d_upper = default_command_range(scene, mc if mc is not None else 0.5)
    tmax = None
    if max_tension is not None:
        tmax = checked_finite("max_tension", _per_tendon("max_tension", max_tension, n))
        if np.any(tmax <= 0):
            raise ValueError(f"max_tension must be > 0 (N), got {tmax}")
        tension_mode = np.array([t.mode == "tension" for t in scene.tendons])
        d_upper = np.where(tension_mode, tmax, d_upper)
    lo = d_lower if lower is None else _per_tendon("lower", lower, n)
    hi = d_upper if upper is None else _per_tendon("upper", upper, n)
    for i, t in enumerate(scene.tendons):
        if t.mode == "tension" and not np.isfinite(hi[i]):
            raise ValueError(
                f"upper[{i}] is needed: tendon {i} is in tension mode (give upper= or max_tension=)"
            )
        if t.mode == "tension" and lo[i] < 0:
            raise ValueError(f"lower[{i}] is a tension and must be >= 0 (tendons never push)")
    checked_finite("lower", lo)
    checked_finite("upper", hi)
    if np.any(hi <= lo):
        bad = int(np.flatnonzero(hi <= lo)[0])
        raise ValueError(f"upper[{bad}] = {hi[bad]} must be above lower[{bad}] = {lo[bad]}")
    weights = {
        "tension_weight": tension_weight,
        "tension_limit_weight": tension_limit_weight,
        "contraction_weight": contraction_weight,
    }
    for name, w in weights.items():
        if not (np.isfinite(w) and w >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {w}")
    contraction = None
    if mc is not None:
        contraction = jnp.asarray(mc * np.asarray(scene.robot.stacked("length"), float))
    return CommandLimits(
        lower=jnp.asarray(lo),
        upper=jnp.asarray(hi),
        tension_weight=jnp.asarray(float(tension_weight)),
        max_tension=None if tmax is None else jnp.asarray(tmax),
        tension_limit_weight=jnp.asarray(float(tension_limit_weight)),
        max_contraction=contraction,
        contraction_weight=jnp.asarray(float(contraction_weight)),
    )
