"""What an inverse call asks for, checked once: command limits and penalties, the reached
tolerances, the starts and their seed, the solver's options and step budget."""

from collections.abc import Mapping

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .. import _deprecated
from .._statics.options import SolverOptions, resolve_options
from .problem import CommandLimits, make_limits


class Settings(eqx.Module):
    """Everything of a call but the target, checked once."""

    limits: CommandLimits
    reached_tol: float = eqx.field(static=True)
    orientation_tol: float = eqx.field(static=True)
    n_starts: int = eqx.field(static=True)
    max_steps: int = eqx.field(static=True)
    rtol: float = eqx.field(static=True)
    atol: float = eqx.field(static=True)
    seed: int = eqx.field(static=True)
    options: SolverOptions = eqx.field(static=True)


def check_settings(scene, kw) -> Settings:
    """The settings from ``kw`` (every key of :data:`DEFAULTS`, popped), each checked: a bad
    value raises naming its option before anything compiles."""
    reached_tol = float(kw.pop("reached_tol"))
    if not (np.isfinite(reached_tol) and reached_tol > 0):
        raise ValueError(f"reached_tol must be > 0 (m), got {reached_tol}")
    orientation_tol = float(kw.pop("orientation_tol"))
    if not (np.isfinite(orientation_tol) and orientation_tol > 0):
        raise ValueError(f"orientation_tol must be > 0 (rad), got {orientation_tol}")
    n_starts, max_steps = int(kw.pop("n_starts")), int(kw.pop("max_steps"))
    if n_starts < 1:
        raise ValueError(f"n_starts must be >= 1, got {n_starts}")
    if max_steps < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}")
    options, legacy = kw.pop("options"), kw.pop("solver_options")
    if legacy is not None:
        _deprecated.warn("solver_options=", "options=pacjax.SolverOptions(...)")
        if not isinstance(legacy, Mapping):
            raise TypeError("solver_options must be a dict of pacjax.SolverOptions fields")
    options = resolve_options(options, **(legacy or {}))
    limits = make_limits(
        scene,
        kw.pop("lower"),
        kw.pop("upper"),
        kw.pop("max_tension"),
        kw.pop("max_contraction"),
        kw.pop("tension_weight"),
        kw.pop("tension_limit_weight"),
        kw.pop("contraction_weight"),
    )
    return Settings(
        limits=limits,
        reached_tol=reached_tol,
        orientation_tol=orientation_tol,
        n_starts=n_starts,
        max_steps=max_steps,
        rtol=float(kw.pop("rtol")),
        atol=float(kw.pop("atol")),
        seed=int(kw.pop("seed")),
        options=options,
    )


DEFAULTS = dict(
    lower=None,
    upper=None,
    max_tension=None,
    max_contraction=0.5,
    tension_weight=1e-5,
    tension_limit_weight=1e-2,
    contraction_weight=10.0,
    reached_tol=1e-4,
    orientation_tol=1e-2,
    n_starts=4,
    max_steps=60,
    rtol=1e-4,
    atol=1e-12,
    seed=0,
    options=None,
    solver_options=None,
)


def without_tension_weight(limits: CommandLimits) -> CommandLimits:
    return eqx.tree_at(lambda x: x.tension_weight, limits, jnp.zeros_like(limits.tension_weight))


def random_starts(settings: Settings, n: int, key_offset: int = 0) -> np.ndarray:
    lo, hi = np.asarray(settings.limits.lower), np.asarray(settings.limits.upper)
    rng = np.random.default_rng([settings.seed, key_offset])
    # Away from the bounds, where the sigmoid is not flat and tendons are neither slack nor
    # fully pulled.
    return lo + (hi - lo) * rng.uniform(0.05, 0.6, (n, lo.size))


def is_reached(settings, error, angle, ok):
    """Within both tolerances, at a converged equilibrium."""
    return (error <= settings.reached_tol) & (angle <= settings.orientation_tol) & ok


def tolerances(settings):
    """``(rtol, atol, max_steps)`` of :func:`solve_one` / :func:`solve_many`: the tolerances
    traced (one compiled solver for all of them), the step budget static."""
    return jnp.asarray(settings.rtol), jnp.asarray(settings.atol), settings.max_steps


def with_defaults(kwargs):
    """The caller's options over :data:`DEFAULTS`; an unknown one is a ``TypeError``."""
    unknown = set(kwargs) - set(DEFAULTS)
    if unknown:
        raise TypeError(f"unknown option(s): {', '.join(sorted(unknown))}")
    return {**DEFAULTS, **kwargs}
