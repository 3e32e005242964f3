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

import dataclasses
import time

import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._jit import jit
from .._model.inputs import check_scene, static_load_sites
from .._model.scene import Scene
from .._statics.batch import solve_batch
from .._statics.equilibrium import solve_equilibrium
from .problem import (
    Solve,
    checked_array,
    checked_finite,
    make_target,
    solve_many,
    solve_one,
    taut_many,
    taut_one,
    tensions_at,
)
from .results import InverseResult, Tracking, Workspace, inverse_result
from .settings import (
    check_settings,
    is_reached,
    random_starts,
    tolerances,
    with_defaults,
    without_tension_weight,
)

#: A solution whose error is above this fraction of ``reached_tol`` is polished: solved again
#: from where it stopped without the low-tension term, which otherwise biases it (by
#: ``~tension_weight^2``). Gauss-Newton steps are minimum-norm, so the polish barely moves
#: along the commands that do not change the pose and keeps the low tension found.
_POLISH = 0.1


def _check_start(scene, name, value, shape):
    arr = checked_finite(name, checked_array(name, value))
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    return arr


def _result(scene, settings, best: Solve, starts) -> InverseResult:
    """The :class:`InverseResult` of the best solve; ``best.iterations`` counts all starts."""
    error, angle, ok = (np.asarray(x) for x in (best.error, best.orientation_error, best.converged))
    reached = is_reached(settings, error, angle, ok)
    u, q = best.controls, best.q
    tensions = (
        tensions_at(scene, q, u)
        if np.ndim(u) == 1
        else jax.vmap(lambda a, b: tensions_at(scene, a, b))(q, u)
    )
    return InverseResult(
        controls=jnp.asarray(u),
        q=jnp.asarray(q),
        error=jnp.asarray(best.error),
        orientation_error=jnp.asarray(best.orientation_error),
        reached=jnp.asarray(reached),
        position=jnp.asarray(best.position),
        rotation=jnp.asarray(best.rotation),
        tensions=jnp.asarray(tensions),
        iterations=jnp.asarray(best.iterations),
        starts=jnp.asarray(starts),
        converged=jnp.asarray(best.converged),
        result=inverse_result(reached, best.converged),
    )


def _cost(settings, error, angle, weight):
    """Ranks candidate solutions: position error plus weighted orientation error (m)."""
    return np.asarray(error) + np.asarray(weight) * np.asarray(angle)


def _reference_point(tgt, axis):
    """The mean of the target's known points: what the nearest workspace samples are near."""
    return np.nanmean(np.where(np.asarray(tgt.mask) > 0, np.asarray(tgt.points), np.nan), axis)


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
    settings = check_settings(scene, with_defaults(kwargs))
    tgt = make_target(scene, target, rotation, orientation_weight, sites)
    starts = _single_starts(scene, settings, tgt, controls0, q0, workspace)
    weight = tgt.orientation_weight
    best, best_cost, iterations = None, np.inf, 0
    k = 0
    for k, (u, q) in enumerate(starts, start=1):  # noqa: B007  (k: starts used)
        out, steps = _solve_from_start(scene, tgt, settings, u, q)
        iterations += steps
        cost = float(_cost(settings, out.error, out.orientation_error, weight))
        if best is None or cost < best_cost:
            best, best_cost = out, cost
        if _reached_one(settings, out):
            break
    return _result(scene, settings, dataclasses.replace(best, iterations=iterations), k)


def _single_starts(scene, settings, tgt, controls0, q0, workspace):
    """The starts of :func:`inverse_statics`, in the order they are tried: ``controls0`` (with
    ``q0``), the nearest ``workspace`` samples, random commands; ``n_starts`` of them, each
    ``(commands, equilibrium or None: to be solved)``."""
    starts = []
    if controls0 is not None:
        u = _check_start(scene, "controls0", controls0, (scene.n_tendons,))
        q = None if q0 is None else _check_start(scene, "q0", q0, (scene.n_dofs,))
        starts.append((u, q))
    elif q0 is not None:
        raise ValueError("q0 needs controls0 (the commands it is the equilibrium of)")
    if workspace is not None:
        for i in workspace.nearest(_reference_point(tgt, 0), settings.n_starts):
            starts.append((np.asarray(workspace.controls[i]), np.asarray(workspace.q[i])))
    starts += [(u, None) for u in random_starts(settings, settings.n_starts)]
    return starts[: settings.n_starts]


def _reached_one(settings, out: Solve) -> bool:
    angle, ok = float(out.orientation_error), bool(out.converged)
    return is_reached(settings, float(out.error), angle, ok)


def _solve_from_start(scene, tgt, settings, u, q):
    """One start of :func:`inverse_statics`: ``(the solve, iterations)``.

    Solves the equilibrium at ``u`` when ``q`` is None; a solve that stopped short of the target
    at a converged equilibrium is tried again from its slack tendons pulled taut, and the closer
    of the two kept.
    """
    if q is None:
        q = solve_equilibrium(scene, u, options=settings.options).q
    out, iterations = _solve_polished(scene, tgt, settings, jnp.asarray(u), jnp.asarray(q))
    if bool(out.converged) and not _reached_one(settings, out):
        u_taut, changed = taut_one(scene, settings.limits, out.controls, out.q)
        if bool(changed):
            again, steps = _solve_polished(scene, tgt, settings, u_taut, out.q)
            iterations += steps
            weight = tgt.orientation_weight
            old = float(_cost(settings, out.error, out.orientation_error, weight))
            if float(_cost(settings, again.error, again.orientation_error, weight)) < old:
                out = again
    return out, iterations


def _solve_polished(scene, tgt, settings, u, q):
    """Levenberg-Marquardt from ``(u, q)``, then the polish without the tension preference
    where that preference biased a converged solve; ``(the better solve, iterations)``."""
    tol = tolerances(settings)
    out = solve_one(scene, tgt, settings.limits, u, q, *tol, settings.options)
    steps = int(out.iterations)
    if bool(out.converged) and float(out.error) > _POLISH * settings.reached_tol:
        free = without_tension_weight(settings.limits)
        polished = solve_one(scene, tgt, free, out.controls, out.q, *tol, settings.options)
        steps += int(polished.iterations)
        if bool(polished.converged) and float(polished.error) < float(out.error):
            out = polished
    return out, steps


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
    settings = check_settings(scene, with_defaults(kwargs))
    tgt = make_target(scene, targets, rotation, orientation_weight, sites, batched=True)
    n = tgt.points.shape[0]
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    chunk = min(chunk_size, n)
    starts = _BatchStarts(scene, settings, tgt, controls0, workspace, chunk)
    best, cost = None, np.full(n, np.inf)
    starts_used = np.zeros(n, int)
    todo = np.arange(n)
    for k in range(settings.n_starts):
        u, q = starts(k, todo)
        out = _solve_round(scene, tgt, settings, todo, u, q, chunk)
        best = _keep_best(settings, tgt, best, cost, todo, out)
        starts_used[todo] += 1
        reached = is_reached(settings, best.error, best.orientation_error, best.converged)
        todo = np.flatnonzero(~reached)
        if todo.size == 0:
            break
    return _result(scene, settings, best, starts_used)


class _BatchStarts:
    """Start ``k`` of every target of :func:`inverse_statics_batch`, in the order of
    :func:`inverse_statics`: ``controls0`` (when given), then the target's nearest
    ``workspace`` samples, then random commands (drawn for start ``k``)."""

    def __init__(self, scene, settings, tgt, controls0, workspace, chunk):
        self.scene, self.settings, self.workspace, self.chunk = scene, settings, workspace, chunk
        n = tgt.points.shape[0]
        self.n = n
        #: (n, j): the workspace samples of the starts after ``controls0``, nearest first.
        self.near = np.zeros((n, 0), int)
        if workspace is not None:
            self.near = workspace.nearest(_reference_point(tgt, 1), settings.n_starts)
        self.u0 = None
        if controls0 is not None:
            u0 = checked_finite("controls0", checked_array("controls0", controls0))
            self.u0 = np.broadcast_to(u0, (n, scene.n_tendons))
            self.near = self.near[:, : settings.n_starts - 1]

    def __call__(self, k, rows):
        """Commands and equilibria of start ``k`` for the targets ``rows`` (aligned with
        ``rows``); the equilibria of other than workspace samples are solved."""
        j = k - (self.u0 is not None)
        if j < 0:
            u = self.u0[rows]
        elif j < self.near.shape[1]:
            idx = self.near[rows, j]
            ws = self.workspace
            return np.asarray(ws.controls, float)[idx], np.asarray(ws.q, float)[idx]
        else:
            u = random_starts(self.settings, self.n, key_offset=k)[rows]
        options = self.settings.options
        eq = solve_batch(self.scene, u, chunk_size=self.chunk, progress=False, options=options)
        return u, np.asarray(eq.q, float)


def _solve_round(scene, tgt, settings, rows, u, q, chunk) -> Solve:
    """One start for the targets ``rows`` from ``u``, ``q`` (aligned with ``rows``):
    Levenberg-Marquardt and the polish, then the retry from slack tendons pulled taut where a
    solve stopped short. NumPy fields, aligned with ``rows``."""
    out = _solve_rows(scene, tgt, settings, rows, u, q, chunk)
    _retry_taut(scene, tgt, settings, rows, out, chunk)
    return out


def _keep_best(settings, tgt, best, cost, rows, out):
    """Merges one round's solves ``out`` of the targets ``rows`` into ``best`` (all targets;
    allocated on the first round): a solve replaces a row where it ranks better than
    ``cost`` (updated in place), and the iterations of every solve add up."""
    if best is None:
        n = cost.shape[0]
        best = jtu.tree_map(lambda x: np.zeros((n,) + x.shape[1:], x.dtype), out)
        best = dataclasses.replace(best, iterations=np.zeros(n, int))
    c = _cost(settings, out.error, out.orientation_error, np.asarray(tgt.orientation_weight)[rows])
    better = c < cost[rows]
    _put(best, out, better, at=rows)
    cost[rows[better]] = c[better]
    best.iterations[rows] += out.iterations
    return best


#: The fields of :class:`Solve` that a better solve replaces (its iterations add up instead).
_MERGED = tuple(f.name for f in dataclasses.fields(Solve) if f.name != "iterations")


def _put(into: Solve, new: Solve, where, at=None) -> None:
    """Copies the rows ``where`` of ``new`` into the rows ``at[where]`` (``where`` without
    ``at``) of ``into``, in place: every field but ``iterations``, which the callers add up."""
    rows = where if at is None else at[where]
    for field in _MERGED:
        getattr(into, field)[rows] = getattr(new, field)[where]


def _head(out: Solve, size) -> Solve:
    """The first ``size`` rows of a padded chunk's solves, as writable NumPy arrays."""
    return jtu.tree_map(lambda x: np.array(x)[:size], out)


def _padded(rows, chunk):
    """``rows`` in pieces of ``chunk``, each with its padded index array (every call of a
    batched solver gets ``chunk`` rows: one compiled program)."""
    for begin in range(0, rows.size, chunk):
        part = np.arange(begin, min(begin + chunk, rows.size))
        yield part, np.concatenate([part, np.repeat(part[-1:], chunk - part.size)])


def _solve_rows(scene, tgt, settings, rows, u, q, chunk) -> Solve:
    """Levenberg-Marquardt and the polish for the targets ``rows`` from ``u``, ``q`` (aligned
    with ``rows``), chunk by chunk; NumPy fields aligned with ``rows``."""
    parts = []
    for part, pad in _padded(rows, chunk):
        sub = jtu.tree_map(lambda x, p=rows[pad]: x[p], tgt)
        parts.append(_solve_chunk(scene, sub, settings, u[pad], q[pad], part.size, chunk))
    return jtu.tree_map(lambda *xs: np.concatenate(xs), *parts)


def _solve_chunk(scene, sub, settings, u, q, size, chunk) -> Solve:
    """One padded chunk (targets ``sub``, starts ``u``, ``q``): Levenberg-Marquardt, then the
    polish without the tension preference where it biased a converged solve; the first
    ``size`` rows."""
    tol = tolerances(settings)
    u, q = jnp.asarray(u), jnp.asarray(q)
    out = _head(solve_many(scene, sub, settings.limits, u, q, *tol, settings.options), size)
    polish = out.converged & (out.error > _POLISH * settings.reached_tol)
    if np.any(polish):
        free = without_tension_weight(settings.limits)
        u, q = jnp.asarray(_pad_rows(out.controls, chunk)), jnp.asarray(_pad_rows(out.q, chunk))
        again = _head(solve_many(scene, sub, free, u, q, *tol, settings.options), size)
        _put(out, again, polish & again.converged & (again.error < out.error))
        iterations = out.iterations + np.where(polish, again.iterations, 0)
        out = dataclasses.replace(out, iterations=iterations)
    return out


def _retry_taut(scene, tgt, settings, rows, out: Solve, chunk) -> None:
    """Rows of ``out`` that stopped short with slack tendons: again from those tendons pulled
    taut; a retry that ranks better replaces the row (in place), its iterations add up."""
    reached = is_reached(settings, out.error, out.orientation_error, out.converged)
    miss = np.flatnonzero(out.converged & ~reached)
    if miss.size == 0:
        return
    u_taut, changed = np.zeros((miss.size, scene.n_tendons)), np.zeros(miss.size, bool)
    for part, pad in _padded(miss, chunk):
        u_p, c_p = taut_many(scene, settings.limits, out.controls[miss[pad]], out.q[miss[pad]])
        u_taut[part], changed[part] = np.asarray(u_p)[: part.size], c_p[: part.size]
    sel = miss[changed]
    if sel.size == 0:
        return
    again = _solve_rows(scene, tgt, settings, rows[sel], u_taut[changed], out.q[sel], chunk)
    weight = np.asarray(tgt.orientation_weight)[rows[sel]]
    old = _cost(settings, out.error[sel], out.orientation_error[sel], weight)
    take = _cost(settings, again.error, again.orientation_error, weight) < old
    _put(out, again, take, at=sel)
    out.iterations[sel] += again.iterations


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
    kw = with_defaults(kwargs)
    check_settings(scene, dict(kw))  # check the options before the first solve
    tgt = make_target(scene, waypoints, rotation, orientation_weight, sites, batched=True)
    start = time.perf_counter()
    results = []
    u, q = controls0, q0
    for i in range(tgt.points.shape[0]):
        rot_i = None if rotation is None else np.asarray(tgt.rotation[i])
        res = inverse_statics(
            scene,
            np.asarray(waypoints, float)[i],
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
    return _tracking(results, time.perf_counter() - start)


def _tracking(results, seconds) -> Tracking:
    """The waypoints' results stacked, with the largest command jump between neighbours."""
    stacked = jtu.tree_map(lambda *xs: jnp.stack(xs), *results)
    u_all = np.asarray(stacked.controls)
    n = len(results)
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
    settings = check_settings(scene, with_defaults({**kwargs, "seed": seed}))
    lo, hi = np.asarray(settings.limits.lower), np.asarray(settings.limits.upper)
    rng = np.random.default_rng(seed)
    u = lo + (hi - lo) * rng.uniform(0.0, 1.0, (int(n), lo.size))
    eq = solve_batch(scene, u, chunk_size=chunk_size, progress=False, options=settings.options)
    tip = _tip_batch(scene, eq.q)
    return Workspace(controls=jnp.asarray(u), q=eq.q, tip=tip, converged=eq.converged & eq.stable)


@jit
def _tip_batch(scene, q):
    n = scene.n_segments - 1
    return jax.vmap(lambda x: scene.frames(x, np.asarray([n]), jnp.ones(1, x.dtype))[1][0])(q)
