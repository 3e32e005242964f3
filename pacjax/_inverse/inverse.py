"""Inverse statics: the tendon commands whose equilibrium puts the robot where the user wants it.

The forward map ``u -> q*(u) -> pose`` has no closed form (the paper names this as its main
limitation), but it is differentiable: :func:`pacjax.solve_equilibrium` gives ``dq*/du`` by the
implicit function theorem (one linear solve at the equilibrium). The inverse problem is then a
bounded nonlinear least-squares problem in the commands, solved with ``optimistix``'s
Levenberg-Marquardt method. Its residual (in metres) stacks:

- the target error: tip position, tip position and orientation (``orientation_weight`` metres
  per radian), or the positions of marker sites (NaN targets are skipped);
- a preference for low tension, ``tension_weight * T`` (m/N): among the commands that reach a
  target (the paper's robot has 9 tendons for a 3D tip position) it picks the least taut, so
  antagonistic tendons do not fight. The default 1e-5 m/N makes 10 N of tension cost as much
  as 0.1 mm of error; it biases a reached target by ~5 um on the paper's robot. A solution biased
  by more than a tenth of ``reached_tol`` is polished without it (minimum-norm Gauss-Newton
  steps keep the low tension found). The optimum often has tendons just at the edge of slack,
  where the tension has a kink: Levenberg-Marquardt then converges slowly there, and many
  solves end on ``max_steps`` (median 60 on the paper's robot) with the target reached;
- tension limits ``max_tension`` (N) as a hinge ``tension_limit_weight * max(T - T_max, 0)``;
- the segments' contraction limit as a hinge on ``-dL - max_contraction * L`` (m).

Command bounds (motor range) are exact: the solver works on ``z`` with
``u = lower + (upper - lower) * sigmoid(z)``. The default range of a length-mode tendon is
``[0, max_contraction * spanned length]``: with the default ``max_contraction = 0.5`` a tendon of
the paper's robot may be pulled in by 67.7 mm, its segments' 0-70 mm contraction range. Tension
mode tendons need ``upper`` or ``max_tension``.

Each solve starts from a command (given, from the nearest sample of a :class:`Workspace`, or
random within the bounds drawn from ``seed``) and the equilibrium there; when the error is above
``reached_tol`` after ``max_steps`` iterations, the next start is tried (``n_starts`` in all) and
the best result kept. A target out of reach therefore returns the closest pose found, with
``reached=False``: it is never reported as reached. :func:`inverse_statics_batch` solves many
targets at once (``vmap``); :func:`track` follows a path with warm starts (each waypoint starts
from the previous commands and equilibrium), so the commands vary smoothly.
"""

from __future__ import annotations

import time
from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .. import _deprecated
from .._model.inputs import check_scene, static_load_sites
from .._model.scene import Scene
from .._statics.batch import solve_batch
from .._statics.equilibrium import solve_equilibrium
from .._statics.options import SolverOptions, resolve_options
from .problem import (
    CommandLimits,
    checked_array,
    checked_finite,
    make_limits,
    make_target,
    solve_many,
    solve_one,
    taut_many,
    taut_one,
    tensions_at,
)
from .results import InverseResult, Tracking, Workspace, inverse_result


class _Settings(eqx.Module):
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


def _settings(scene, kw) -> _Settings:
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
    return _Settings(
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


_DEFAULTS = dict(
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


#: A solution whose error is above this fraction of ``reached_tol`` is polished: solved again
#: from where it stopped without the low-tension term, which otherwise biases it (by
#: ``~tension_weight^2``). Gauss-Newton steps are minimum-norm, so the polish barely moves
#: along the commands that do not change the pose and keeps the low tension found.
_POLISH = 0.1


def _without_tension_weight(limits: CommandLimits) -> CommandLimits:
    return eqx.tree_at(lambda x: x.tension_weight, limits, jnp.zeros_like(limits.tension_weight))


def _random_starts(settings: _Settings, n: int, key_offset: int = 0) -> np.ndarray:
    lo, hi = np.asarray(settings.limits.lower), np.asarray(settings.limits.upper)
    rng = np.random.default_rng([settings.seed, key_offset])
    # Away from the bounds, where the sigmoid is not flat and tendons are neither slack nor
    # fully pulled.
    return lo + (hi - lo) * rng.uniform(0.05, 0.6, (n, lo.size))


def _check_start(scene, name, value, shape):
    arr = checked_finite(name, checked_array(name, value))
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    return arr


def _is_reached(settings, error, angle, ok):
    return (error <= settings.reached_tol) & (angle <= settings.orientation_tol) & ok


def _result(scene, settings, u, q, error, angle, tip, rot, ok, iterations, starts):
    reached = _is_reached(settings, np.asarray(error), np.asarray(angle), np.asarray(ok))
    tensions = (
        tensions_at(scene, q, u)
        if np.ndim(u) == 1
        else jax.vmap(lambda a, b: tensions_at(scene, a, b))(q, u)
    )
    return InverseResult(
        controls=jnp.asarray(u),
        q=jnp.asarray(q),
        error=jnp.asarray(error),
        orientation_error=jnp.asarray(angle),
        reached=jnp.asarray(reached),
        position=jnp.asarray(tip),
        rotation=jnp.asarray(rot),
        tensions=jnp.asarray(tensions),
        iterations=jnp.asarray(iterations),
        starts=jnp.asarray(starts),
        converged=jnp.asarray(ok),
        result=inverse_result(reached, ok),
    )


def _cost(settings, error, angle, weight):
    """Ranks candidate solutions: position error plus weighted orientation error (m)."""
    return np.asarray(error) + np.asarray(weight) * np.asarray(angle)


# ------------------------------------------------------------------------------ public API
def inverse_statics(
    scene: Scene,
    target,
    *,
    rotation=None,
    orientation_weight: float = 0.1,
    sites=None,
    controls0=None,
    q0=None,
    workspace: Workspace | None = None,
    **kwargs,
) -> InverseResult:
    """Tendon commands whose equilibrium (under the scene's loads) reaches ``target``.

    Args:
        scene: the :class:`Scene` (its loads, e.g. a payload, change the answer).
        target: tip position (3,) in m; with ``sites``, the positions (m, 3) of those marker
            sites (NaN: ignored coordinate).
        rotation: (3, 3) target tip orientation (world frame): a pose target.
        orientation_weight: metres of position error worth one radian of orientation error.
        sites: marker sites ``((segment, s), ...)`` or ``((segment, s, offset_xyz), ...)``.
        controls0: first start (default: the nearest ``workspace`` sample, else a random
            command drawn from ``seed``).
        q0: equilibrium (or a nearby configuration) at ``controls0``; default: solved.
        workspace: a :class:`Workspace` whose nearest samples give the starts.
        lower, upper: command bounds (n_tendons,) or scalars; default
            :func:`default_command_range`.
        max_tension: tension limit (N), scalar or per tendon (None: none).
        max_contraction: segment contraction limit as a fraction of ``L`` (default 0.5: the
            paper's robot contracts 0-70 mm of 135.4 mm); also sets the default ``upper``.
        tension_weight: low-tension preference (m/N), default 1e-5.
        tension_limit_weight, contraction_weight: weights of the limit hinges (m/N, m/m).
        reached_tol: position error (m) below which the target counts as reached (1e-4).
        orientation_tol: orientation error (rad) for a pose target to count as reached (0.01).
        n_starts: starts tried, in order, until one reaches the target (default 4).
        max_steps: Levenberg-Marquardt iterations per start (default 60).
        rtol, atol: Levenberg-Marquardt stopping tolerances on ``z`` and the residual.
        seed: seed of the random starts.
        options: :class:`pacjax.SolverOptions` of the equilibrium solves (default
            ``SolverOptions()``).
        solver_options: deprecated: a dict of :class:`pacjax.SolverOptions` fields (use
            ``options``).

    Returns:
        An :class:`InverseResult`; ``reached`` is False (and the closest pose found is
        returned) when no start reached the target.
    """
    check_scene(scene)
    scene = static_load_sites(scene)
    settings = _settings(scene, _kwargs(kwargs))
    tgt = make_target(scene, target, rotation, orientation_weight, sites)
    starts = []
    if controls0 is not None:
        u = _check_start(scene, "controls0", controls0, (scene.n_tendons,))
        q = None if q0 is None else _check_start(scene, "q0", q0, (scene.n_dofs,))
        starts.append((u, q))
    elif q0 is not None:
        raise ValueError("q0 needs controls0 (the commands it is the equilibrium of)")
    if workspace is not None:
        ref = np.nanmean(np.where(np.asarray(tgt.mask) > 0, np.asarray(tgt.points), np.nan), 0)
        for i in workspace.nearest(ref, settings.n_starts):
            starts.append((np.asarray(workspace.controls[i]), np.asarray(workspace.q[i])))
    starts += [(u, None) for u in _random_starts(settings, settings.n_starts)]
    starts = starts[: settings.n_starts]

    tol = (jnp.asarray(settings.rtol), jnp.asarray(settings.atol), settings.max_steps)

    def solve_from(u, q):
        """Levenberg-Marquardt from ``(u, q)``, then the polish; (result, iterations)."""
        out = solve_one(scene, tgt, settings.limits, u, q, *tol, settings.options)
        steps = int(out[-1])
        if bool(out[6]) and float(out[2]) > _POLISH * settings.reached_tol:
            free = _without_tension_weight(settings.limits)
            polished = solve_one(scene, tgt, free, out[0], out[1], *tol, settings.options)
            steps += int(polished[-1])
            if bool(polished[6]) and float(polished[2]) < float(out[2]):
                out = polished
        return out, steps

    def reached(out):
        return _is_reached(settings, float(out[2]), float(out[3]), bool(out[6]))

    def cost(out):
        return float(_cost(settings, out[2], out[3], tgt.orientation_weight))

    best, iterations = None, 0
    k = 0
    for k, (u, q) in enumerate(starts, start=1):  # noqa: B007  (k: starts used)
        if q is None:
            q = solve_equilibrium(scene, u, options=settings.options).q
        out, steps = solve_from(jnp.asarray(u), jnp.asarray(q))
        iterations += steps
        if bool(out[6]) and not reached(out):  # stopped short: slack tendons pulled taut
            u_taut, changed = taut_one(scene, settings.limits, out[0], out[1])
            if bool(changed):
                again, steps = solve_from(u_taut, out[1])
                iterations += steps
                if cost(again) < cost(out):
                    out = again
        if best is None or cost(out) < best[0]:
            best = (cost(out), out)
        if reached(out):
            break
    u, q, error, angle, tip, rot, ok, _ = best[1]
    return _result(scene, settings, u, q, error, angle, tip, rot, ok, iterations, k)


def _kwargs(kwargs):
    unknown = set(kwargs) - set(_DEFAULTS)
    if unknown:
        raise TypeError(f"unknown option(s): {', '.join(sorted(unknown))}")
    return {**_DEFAULTS, **kwargs}


def _pad_rows(x, size):
    return np.concatenate([x, np.repeat(x[-1:], size - x.shape[0], axis=0)])


def inverse_statics_batch(
    scene: Scene,
    targets,
    *,
    rotation=None,
    orientation_weight: float = 0.1,
    sites=None,
    controls0=None,
    workspace: Workspace | None = None,
    chunk_size: int = 256,
    **kwargs,
) -> InverseResult:
    """:func:`inverse_statics` for many targets at once (``vmap``-ed, in chunks).

    ``targets`` is (n, 3) tip positions or, with ``sites``, (n, m, 3) marker positions;
    ``rotation`` (3, 3) or (n, 3, 3). The starts are those of :func:`inverse_statics`: first
    ``controls0`` (n_tendons,) or (n, n_tendons) when given, then the nearest ``workspace``
    samples, then random commands; the targets not reached after one start try the next
    together, up to ``n_starts``. Other options as
    :func:`inverse_statics`. Returns an :class:`InverseResult` with a leading batch axis.
    """
    check_scene(scene)
    scene = static_load_sites(scene)
    settings = _settings(scene, _kwargs(kwargs))
    tgt = make_target(scene, targets, rotation, orientation_weight, sites, batched=True)
    n = tgt.points.shape[0]
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    chunk = min(chunk_size, n)
    nt = scene.n_tendons
    # Start k of every target: with a workspace, its (k+1)-th nearest sample (after
    # controls0, when given), as inverse_statics does; then random commands.
    near = np.zeros((n, 0), int)
    if workspace is not None:
        ref = np.nanmean(np.where(np.asarray(tgt.mask) > 0, np.asarray(tgt.points), np.nan), 1)
        near = workspace.nearest(ref, settings.n_starts)
    if controls0 is not None:
        u0 = np.broadcast_to(
            checked_finite("controls0", checked_array("controls0", controls0)), (n, nt)
        )
        near = near[:, : settings.n_starts - 1]

    def start(k, rows):
        """Commands and equilibria of start ``k`` for the targets ``rows`` (full-size arrays)."""
        u, q = np.zeros((n, nt)), np.zeros((n, scene.n_dofs))
        j = k - (controls0 is not None)
        if j < 0:
            u[rows] = u0[rows]
        elif j < near.shape[1]:
            idx = near[rows, j]
            u[rows], q[rows] = np.asarray(workspace.controls)[idx], np.asarray(workspace.q)[idx]
            return u, q
        else:
            u[rows] = _random_starts(settings, n, key_offset=k)[rows]
        q[rows] = np.asarray(solve_batch(scene, u[rows], chunk_size=chunk, progress=False).q)
        return u, q

    tol = (jnp.asarray(settings.rtol), jnp.asarray(settings.atol), settings.max_steps)
    weight = np.asarray(tgt.orientation_weight)

    def padded(rows):
        """``rows`` in pieces of ``chunk``, each with its padded index array."""
        for begin in range(0, rows.size, chunk):
            part = np.arange(begin, min(begin + chunk, rows.size))
            yield part, np.concatenate([part, np.repeat(part[-1:], chunk - part.size)])

    def solve_rows(rows, u, q):
        """Levenberg-Marquardt and the polish for the targets ``rows`` from ``u``, ``q``
        (aligned with ``rows``), chunk by chunk; the 7 result fields and the iterations."""
        parts = []
        for part, pad in padded(rows):
            sub = jtu.tree_map(lambda x, p=rows[pad]: x[p], tgt)
            u_p, q_p = jnp.asarray(u[pad]), jnp.asarray(q[pad])
            out = solve_many(scene, sub, settings.limits, u_p, q_p, *tol, settings.options)
            out = [np.array(x)[: part.size] for x in out]
            polish = out[6] & (out[2] > _POLISH * settings.reached_tol)
            if np.any(polish):
                free = _without_tension_weight(settings.limits)
                again = solve_many(
                    scene,
                    sub,
                    free,
                    jnp.asarray(_pad_rows(out[0], chunk)),
                    jnp.asarray(_pad_rows(out[1], chunk)),
                    *tol,
                    settings.options,
                )
                again = [np.asarray(x)[: part.size] for x in again]
                take = polish & again[6] & (again[2] < out[2])
                for f, x in zip(out[:7], again[:7], strict=True):
                    f[take] = x[take]
                out[7] = out[7] + np.where(polish, again[7], 0)
            parts.append(out)
        return [np.concatenate(f) for f in zip(*parts, strict=True)]

    def retry_taut(rows, out):
        """Rows that stopped short with slack tendons: again from those tendons pulled taut."""
        miss = np.flatnonzero(out[6] & ~_is_reached(settings, out[2], out[3], out[6]))
        if miss.size == 0:
            return
        u_taut, changed = np.zeros((miss.size, nt)), np.zeros(miss.size, bool)
        for part, pad in padded(miss):
            u_p, c_p = taut_many(scene, settings.limits, out[0][miss[pad]], out[1][miss[pad]])
            u_taut[part], changed[part] = np.asarray(u_p)[: part.size], c_p[: part.size]
        sel = miss[changed]
        if sel.size == 0:
            return
        again = solve_rows(rows[sel], u_taut[changed], out[1][sel])
        old = _cost(settings, out[2][sel], out[3][sel], weight[rows[sel]])
        take = _cost(settings, again[2], again[3], weight[rows[sel]]) < old
        for f, x in zip(out[:7], again[:7], strict=True):
            f[sel[take]] = x[take]
        out[7][sel] += again[7]

    fields = None
    cost = np.full(n, np.inf)
    iterations = np.zeros(n, int)
    starts = np.zeros(n, int)
    todo = np.arange(n)
    for k in range(settings.n_starts):
        u_start, q_start = start(k, todo)
        out = solve_rows(todo, u_start[todo], q_start[todo])
        retry_taut(todo, out)
        if fields is None:
            fields = [np.zeros((n,) + x.shape[1:], x.dtype) for x in out[:7]]
        c = _cost(settings, out[2], out[3], weight[todo])
        better = c < cost[todo]
        for f, x in zip(fields, out[:7], strict=True):
            f[todo[better]] = x[better]
        cost[todo[better]] = c[better]
        iterations[todo] += out[7]
        starts[todo] += 1
        reached = _is_reached(settings, fields[2], fields[3], fields[6])
        todo = np.flatnonzero(~reached)
        if todo.size == 0:
            break
    u_best, q, error, angle, tip, rot, ok = fields
    return _result(scene, settings, u_best, q, error, angle, tip, rot, ok, iterations, starts)


def track(
    scene: Scene,
    waypoints,
    *,
    rotation=None,
    orientation_weight: float = 0.1,
    sites=None,
    controls0=None,
    q0=None,
    workspace: Workspace | None = None,
    **kwargs,
) -> Tracking:
    """Commands along a path of targets, each waypoint warm-started from the previous one.

    ``waypoints`` is (n, 3) tip positions or, with ``sites``, (n, m, 3) marker positions
    (``rotation`` (n, 3, 3) for poses). The first waypoint is solved like
    :func:`inverse_statics` (from ``controls0``/``q0``, or ``workspace``, or random starts);
    every later one starts from the previous commands and equilibrium, and falls back to the
    other starts only if that fails. Neighbouring waypoints close together give small
    Levenberg-Marquardt steps, so the commands vary smoothly (:attr:`Tracking.max_command_jump`).
    """
    check_scene(scene)
    kw = _kwargs(kwargs)
    _settings(scene, dict(kw))  # check the options before the first solve
    tgt = make_target(scene, waypoints, rotation, orientation_weight, sites, batched=True)
    n = tgt.points.shape[0]
    start = time.perf_counter()
    results = []
    u, q = controls0, q0
    for i in range(n):
        one = jtu.tree_map(lambda x, i=i: x[i], tgt)
        point = np.asarray(waypoints, float)[i]
        rot_i = None if rotation is None else np.asarray(one.rotation)
        res = inverse_statics(
            scene,
            point,
            rotation=rot_i,
            orientation_weight=orientation_weight,
            sites=sites,
            controls0=u,
            q0=q,
            workspace=workspace if i == 0 else None,
            **kw,
        )
        results.append(res)
        u, q = np.asarray(res.controls), np.asarray(res.q)
    jax.block_until_ready(results[-1])
    seconds = time.perf_counter() - start
    stacked = jtu.tree_map(lambda *xs: jnp.stack(xs), *results)
    u_all = np.asarray(stacked.controls)
    jump = float(np.max(np.abs(np.diff(u_all, axis=0)))) if n > 1 else 0.0
    return Tracking(
        waypoints=stacked, max_command_jump=jump, seconds=seconds, waypoints_per_second=n / seconds
    )


def sample_workspace(
    scene: Scene, n: int = 256, *, seed: int = 0, chunk_size: int = 256, **kwargs
) -> Workspace:
    """Forward-solve ``n`` random commands within the bounds (``lower``, ``upper``,
    ``max_contraction`` as :func:`inverse_statics`): the reachable set, and starts for inverse
    solves."""
    check_scene(scene)
    if int(n) < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    settings = _settings(scene, _kwargs({**kwargs, "seed": seed}))
    lo, hi = np.asarray(settings.limits.lower), np.asarray(settings.limits.upper)
    rng = np.random.default_rng(seed)
    u = lo + (hi - lo) * rng.uniform(0.0, 1.0, (int(n), lo.size))
    eq = solve_batch(scene, u, chunk_size=chunk_size, progress=False, options=settings.options)
    tip = _tip_batch(scene, eq.q)
    return Workspace(controls=jnp.asarray(u), q=eq.q, tip=tip, converged=eq.converged & eq.stable)


@eqx.filter_jit
def _tip_batch(scene, q):
    n = scene.n_segments - 1
    return jax.vmap(lambda x: scene.frames(x, np.asarray([n]), jnp.ones(1, x.dtype))[1][0])(q)
