"""Pseudo-transient continuation as an optimistix root finder.

It integrates the damped flow ``D qdot = -F(q)`` with linearised implicit Euler steps ``(I / dt +
dr/dy) dy = -r`` in scaled coordinates (``r = F / (d sigma)``, ``y = q / sigma``, ``d`` the
diagonal of the elastic stiffness). The pseudo-time step ``dt`` grows with the fall of the residual
(switched evolution relaxation), so the steps become Newton steps near the solution; a step that
raises the merit (the energy for conservative scenes; see ``frozen_work`` for the others) is
rejected and ``dt`` shrinks until the step is a short stretch of the flow, which is a descent
direction whatever the curvature. A step ``dy`` lands at the problem's ``moved(y, dy)`` where it
has one (equal to ``y + dy`` to first order; PCC/PAC bending moves as a vector,
:meth:`pacjax._statics.problem.ScaledProblem.moved`). A converged saddle (smallest eigenvalue of
the scaled stiffness below ``-stability_tol``) is left along its negative-curvature direction, a
bounded number of times, and the continuation then goes on until the stiffness is positive again (a
residual below the tolerance next to the saddle is not convergence; for a non-conservative problem
only on the step after the escape, since the flow may lead back to the same point).

With ``ahead`` (the batch's pool, where throughput is the point) a conservative solve also tries
each next step ahead, with the residual at its end and no Jacobian; a solve whose next step lands
within the tolerance ends there, one linearisation sooner, as a Newton solver that stops on the
size of its step does.

Written as an ``optimistix.AbstractRootFinder`` so that ``optimistix.root_find`` runs the loop; its
state's last Jacobian gives the equilibrium's derivatives (:mod:`pacjax._statics.implicit`).
"""

from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Bool, Float

from .._config import MATMUL_PRECISION
from .._results import NONFINITE, STALLED, SUCCESSFUL
from .flow import shifted_flow_step
from .modes import max_abs, saddle_free_step, stiffness_modes
from .ptc_state import PTCState
from .search import MIN_ALPHA, backtrack, descends, energy_slope

_MIN_DT = 1e-10
# Bounds on the growth of dt after a full step (the ratio of the residuals before and after it,
# switched evolution relaxation). A first step from straight can cut the residual a hundredfold;
# a tighter cap leaves the next steps short of Newton along the softest mode (the bending
# planes), which then creeps. A step that overshoots is still cut by the search on the merit.
_DT_GROWTH = (2.0, 100.0)
# Steps after an escape in which a non-conservative solve takes the flow step, not the plain
# Newton step: Newton's converges to the nearest stationary point, the saddle just left (such
# as a straight PAC segment's plane angle at the maximum of its regulariser). The flow step,
# its dt capped by the negative curvature, doubles the distance from the saddle each step:
# 0.05 to pi in six. Bounded, because a point with an indefinite symmetric stiffness can be an
# attractor of the flow (a dead moment bending a twistable rod past ~2 rad), which Newton's
# steps then reach again.
_LEAVING_STEPS = 16
# A converged point reached by the step tried ahead takes its stability from the linearisation
# it was stepped from: only where that stiffness's lowest eigenvalue exceeds the step's size
# times this (the scaled Hessian moves by about its derivative times the step, O(1) in scaled
# coordinates; a generous factor, since the next full step is always there to fall back on).
_AHEAD_EIG_MARGIN = 10.0


def _moved(args, y, dy):
    """The iterate after the step ``dy``: ``args.moved(y, dy)`` where the problem has it (a
    retraction that agrees with ``y + dy`` to first order; see
    :meth:`pacjax._statics.problem.ScaledProblem.moved`), else ``y + dy``."""
    return args.moved(y, dy) if hasattr(args, "moved") else y + dy


class _Point(NamedTuple):
    """The iterate reached by the search and the problem linearised there."""

    y: Float[Array, " n"]
    residual: Float[Array, " n"]
    merit: Float[Array, ""]
    jacobian: Float[Array, "n n"]
    weights: Float[Array, " n"]
    drive: Float[Array, " n"]


class PseudoTransientContinuation(optx.AbstractRootFinder):
    """Root finder for ``fn(y, args) -> (r, (merit, weights))``; see the module docstring.

    One :meth:`step` is a descent direction from the linearisation at ``y`` (:meth:`_descent`),
    a search along it on the merit (:meth:`_search`), the linearisation at the point reached
    (:meth:`_linearise`) and the control of the pseudo-time step (:meth:`_control`). With
    ``ahead``, a conservative solve then tries the next full step (:meth:`_ahead`): where the
    residual at its end is within the tolerance the solve ends there (:meth:`finish`), and
    otherwise the next search starts from that trial's merit.
    """

    rtol: float
    atol: float
    norm: Any = max_abs
    initial_dt: float = 1.0
    max_dt: float = 1e12
    escapes: int = 2
    escape_size: float = 0.05
    stability_tol: float = 1e-12
    symmetric: bool = True
    # When True, ``args.linearise(y) -> (jacobian, (r, aux))`` gives the residual and its
    # Jacobian together (the structured Hessian of :mod:`pacjax._model.hessian`) instead of jacfwd,
    # and, for a symmetric (conservative) problem, ``args.energy(y)`` the merit alone.
    structured: bool = False
    # Non-conservative problem (``symmetric=False``) split as ``r = grad E - Q``: when True,
    # ``fn``'s merit is the energy ``E`` of the conservative part, ``args.energy(y)`` gives it
    # alone and ``args.drive(y)`` gives ``Q``. A step from ``y`` must then not raise
    # ``E(y') - Q(y) . (y' - y)``, the energy with the non-conservative forces frozen at ``y``
    # (its gradient at ``y`` is ``r``). When False the merit is ``|r|^2 / 2``.
    frozen_work: bool = False
    # When True, a conservative solve whose stiffness at the start is positive definite takes
    # Newton steps (dt = max_dt) for as long as each is taken at full length; the first that is
    # shortened or rejected hands over to the continuation from initial_dt. For strain
    # coordinates in which Newton's method converges from the straight start (not the polar
    # ones of PCC/PAC: StrainModel.newton_from_start).
    newton_start: bool = False
    # When True (a conservative problem), each step tries the next one ahead with a residual
    # evaluation (see the module docstring). A solve's programs grow by that evaluation and its
    # result has no linearisation of its own where the step ended it, so only the batch's pool,
    # which neither differentiates nor compiles per call, sets it.
    ahead: bool = False

    @property
    def _frozen(self) -> bool:
        """Whether the merit is the frozen work (non-conservative, with ``frozen_work``)."""
        return self.frozen_work and not self.symmetric

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        del fn, args, options, aux_struct, tags
        n = y.shape[0]
        dtype = y.dtype
        return PTCState(
            residual=jnp.full(f_struct.shape, jnp.inf, dtype),
            merit=jnp.asarray(jnp.inf, dtype),
            jacobian=jnp.eye(n, dtype=dtype),
            weights=jnp.ones(n, dtype),
            dt=jnp.asarray(self.initial_dt, dtype),
            step=jnp.asarray(0),
            escapes=jnp.asarray(0),
            escaping=jnp.asarray(False),
            leaving=jnp.asarray(0),
            eig=jnp.asarray(0.0, dtype),
            eigvals=jnp.ones(n, dtype),
            eigvecs=jnp.eye(n, dtype=dtype),
            escape_dy=jnp.zeros(n, dtype),
            drive=jnp.zeros(n, dtype),
            code=jnp.asarray(SUCCESSFUL),
            ahead_y=y,
            ahead_residual=jnp.full(f_struct.shape, jnp.inf, dtype),
            ahead_merit=jnp.asarray(jnp.inf, dtype),
            ahead_size=jnp.asarray(jnp.inf, dtype),
            ahead_plain=jnp.asarray(False),
        )

    def _converged(self, r) -> Bool[Array, ""]:
        return max_abs(r) <= self.atol

    @property
    def _tries_ahead(self) -> bool:
        return self.ahead and self.symmetric

    def _ahead_done(self, state: PTCState) -> Bool[Array, ""]:
        """Whether the step tried ahead ends the solve: its residual is converged, and the
        stiffness it was stepped from is stable by a margin larger than the step moves it."""
        if not self._tries_ahead:
            return jnp.asarray(False)
        margin = self.stability_tol + _AHEAD_EIG_MARGIN * state.ahead_size
        return (
            self._converged(state.ahead_residual)
            & (state.eig > margin)
            & state.ahead_plain
            & ~state.escaping
            & (state.code == SUCCESSFUL)
        )

    def _plain_near(self, args, state: PTCState) -> Bool[Array, ""]:
        """With ``ahead``: whether the steps from ``state``'s linearisation are plain sums
        ``y + dy``, not ``args.moved``'s moves of PCC/PAC bending vectors. So near a solution,
        where the problem's Jacobian is the polar Hessian (``args.polar_model``), whose Newton
        step the sum is: the step tried ahead is then the search's full step, and a point whose
        bits do not depend on the row's place in a vectorised pool (the moves' arithmetic did,
        at the last bit: rows of a batch differed from run to run where its two pools took
        them in another order)."""
        if not hasattr(args, "moved"):
            return jnp.asarray(True)
        if not hasattr(args, "polar_model"):
            return jnp.asarray(False)
        return args.polar_model(state.residual)

    def _to(self, args, y, dy, plain):
        """The iterate after the step ``dy`` from ``y``: ``y + dy`` where ``plain``, else
        :func:`_moved`'s."""
        if not self._tries_ahead:
            return _moved(args, y, dy)
        return jnp.where(plain, y + dy, _moved(args, y, dy))

    def finish(self, y, state: PTCState):
        """``(y, residual, merit)`` of the solve's result: the point reached by the step tried
        ahead where that ended the solve (:meth:`_ahead_done`), else ``y`` and its own."""
        if not self._tries_ahead:
            return y, state.residual, state.merit
        done = self._ahead_done(state)
        return (
            jnp.where(done, state.ahead_y, y),
            jnp.where(done, state.ahead_residual, state.residual),
            jnp.where(done, state.ahead_merit, state.merit),
        )

    def _wants_escape(self, state: PTCState) -> Bool[Array, ""]:
        return (
            self._converged(state.residual)
            & (state.eig < -self.stability_tol)
            & (state.escapes < self.escapes)
        )

    def step(self, fn, y, args, options, state: PTCState, tags):
        """One iteration from ``y``: a direction, a search along it, the new linearisation.

        The first step (``state.step == 0``) only linearises at ``y`` itself; a converged saddle
        is left by the escape step. Returns the next iterate (``y`` where the step is rejected),
        the state there and ``(merit, weights)`` at it.
        """
        del options, tags
        first = state.step == 0
        escape = self._wants_escape(state) & ~first
        delta, took_newton = self._descent(fn, y, args, state, first, escape)
        # (an escape from a saddle moves as it always has)
        plain = self._plain_near(args, state) & ~escape if self._tries_ahead else None
        alpha, ok = self._search(fn, y, args, state, delta, took_newton, first, escape, plain)
        # No acceptable step even at the smallest length: take the shortest flow step when dt
        # is already tiny (it is a descent direction), else shrink dt and stay.
        tiny_dt = state.dt <= _MIN_DT
        accept = ok | tiny_dt
        alpha = jnp.where(ok, alpha, MIN_ALPHA)
        new = self._linearise(fn, self._to(args, y, alpha * delta, plain), args, state)
        finite = (
            jnp.all(jnp.isfinite(new.residual))
            & jnp.isfinite(new.merit)
            & jnp.all(jnp.isfinite(new.jacobian))
        )
        accept = first | (accept & finite)
        new_state = self._control(state, new, alpha, ok, tiny_dt, accept, finite, first, escape)
        y_next = jnp.where(accept, new.y, y)
        if self._tries_ahead:
            new_state = self._ahead(fn, y_next, args, new_state)
        return y_next, new_state, (new_state.merit, new_state.weights)

    def _ahead(self, fn, y, args, state: PTCState) -> PTCState:
        """``state`` with the next continuation step from ``y`` tried ahead: its end point,
        residual and merit (one residual evaluation, no Jacobian). :meth:`terminate` ends the
        solve there where the residual is converged, and the next :meth:`_search` starts from
        that merit.

        The point is the search's full step (:meth:`_to`); the solve ends there only where it
        is a plain sum (:meth:`_plain_near`)."""
        delta = saddle_free_step(
            state.eigvals, state.eigvecs, state.weights, state.residual, state.dt
        )
        plain = self._plain_near(args, state)
        y_ahead = self._to(args, y, delta, plain)
        r, (merit, _) = fn(y_ahead, args)
        return eqx.tree_at(
            lambda s: (s.ahead_y, s.ahead_residual, s.ahead_merit, s.ahead_size, s.ahead_plain),
            state,
            (y_ahead, r, merit, max_abs(delta), plain),
        )

    def _descent(self, fn, y, args, state: PTCState, first, escape):
        """The step ``delta`` from ``y`` that the search shortens, and ``took_newton``.

        ``delta`` is zero on the first step, ``state.escape_dy`` on an escape, else the
        continuation step from the linearisation in ``state`` (:func:`saddle_free_step` for a
        conservative scene, :meth:`_shifted_flow_step` for the others). ``took_newton`` (``None``
        for a conservative scene) says that it is a plain Newton step that halved the residual.
        """
        # Where the stiffness is indefinite (a saddle or a maximum nearby) the step must still
        # go downhill and must not be drawn to the saddle.
        if self.symmetric:
            newton = saddle_free_step(
                state.eigvals, state.eigvecs, state.weights, state.residual, state.dt
            )
            took_newton = None
        else:
            newton, took_newton = self._shifted_flow_step(fn, y, args, state, first, escape)
        delta = jnp.where(first, 0.0, jnp.where(escape, state.escape_dy, newton))
        return delta, took_newton

    def _shifted_flow_step(self, fn, y, args, state: PTCState, first, escape):
        """The continuation step of a non-conservative scene and whether it is a Newton step
        (:func:`pacjax._statics.flow.shifted_flow_step`); no Newton step on the first step, an
        escape, or while leaving a saddle."""
        return shifted_flow_step(
            lambda y_: fn(y_, args)[0],
            lambda dy: _moved(args, y, dy),
            state.jacobian,
            state.residual,
            state.dt,
            state.eig,
            newton_allowed=~first & ~escape & (state.leaving == 0),
            near_needs_negative=not self.frozen_work,
        )

    def _search(self, fn, y, args, state: PTCState, delta, took_newton, first, escape, plain):
        """The length ``alpha`` of the step along ``delta``, and ``ok``: whether it is acceptable
        (:func:`pacjax._statics.search.backtrack`, on :meth:`_merit_only`).

        The full step is acceptable unchecked on the first step and an escape, and when its
        predicted decrease is within rounding (:meth:`_slope`) or, for a non-conservative
        scene, when it is a Newton step that halved the residual. ``plain`` (with ``ahead``):
        whether the trial points are plain sums (:meth:`_to`).
        """
        merit_only = self._merit_only(fn, y, args, state)
        slope, rounding = self._slope(y, state, delta)
        if self._tries_ahead:
            # Tried at the end of the last step, at this very point (the first step and an
            # escape are taken whatever the merit says).
            m_full = state.ahead_merit
        else:
            m_full = merit_only(_moved(args, y, delta))
        ok_full = descends(m_full, state.merit) | rounding | first | escape
        if not self.symmetric:
            # A Newton step that halved the residual is taken whatever the merit says: near a
            # solution of a soft structure the frozen work misses the stiffness of the
            # follower loads, and the merit of the Newton step can rise.
            ok_full = ok_full | took_newton
        return backtrack(
            lambda alpha: merit_only(self._to(args, y, alpha * delta, plain)),
            state.merit,
            m_full,
            ok_full,
            slope,
            take_any=first | escape,
        )

    def _merit_only(self, fn, y, args, state: PTCState):
        """The merit as a function of the trial point, for the search from ``y``.

        For a conservative scene that is the energy without its gradient (about half the cost
        of the residual) where the problem gives it alone; for a non-conservative one with
        ``frozen_work`` the energy less the work of the forces frozen at ``y``; else ``fn``'s.
        """
        if self.structured and self.symmetric:
            return args.energy
        if self._frozen:

            def frozen_work(y_):
                return args.energy(y_) - jnp.dot(state.drive, y_ - y, precision=MATMUL_PRECISION)

            return frozen_work

        def merit(y_):
            return fn(y_, args)[1][0]

        return merit

    def _slope(self, y, state: PTCState, delta):
        """The merit's slope along ``delta`` at ``y`` and ``rounding`` (take the full step):
        :func:`pacjax._statics.search.energy_slope`. Not for the merit ``|r|^2 / 2``, a sum of
        squares whose rounding is relative to itself: the search halves its steps."""
        if self.symmetric or self.frozen_work:
            return energy_slope(y, state.weights, state.residual, state.merit, delta)
        return jnp.asarray(jnp.nan, y.dtype), False

    def _linearise(self, fn, y, args, state: PTCState) -> _Point:
        """The residual, merit, weights and Jacobian at ``y`` in one evaluation, and the drive.

        ``args.linearise`` for a structured problem, else forward mode through ``fn``. The
        drive (the non-conservative force frozen for the next search) is ``state.drive`` where
        the merit does not use it.
        """

        def with_aux(y_):
            r, aux = fn(y_, args)
            return r, (r, aux)

        if self.structured:
            jac, (r, (merit, weights)) = args.linearise(y)
        else:
            jac, (r, (merit, weights)) = jax.jacfwd(with_aux, has_aux=True)(y)
        drive = args.drive(y) if self._frozen else state.drive
        return _Point(y, r, merit, jac, weights, drive)

    def _control(self, state, new: _Point, alpha, ok, tiny_dt, accept, finite, first, escape):
        """The state after the step: the point ``new`` where ``accept``, else that of ``state``.

        Also the next pseudo-time step (:meth:`_next_dt`), the stiffness modes and escape step
        for the next direction (:func:`stiffness_modes`), the escape bookkeeping and the result
        code (``NONFINITE`` at a non-finite start, ``STALLED``).
        """

        def keep(a, b):
            return jnp.where(accept, a, b)

        jac = keep(new.jacobian, state.jacobian)
        eigvals, eigvecs, escape_dy = stiffness_modes(
            jac, new.weights, self.escape_size, self.stability_tol
        )
        eig = eigvals[0]
        dt = self._next_dt(state, new.residual, alpha, accept, first, escape, eig)
        code = jnp.where(first & ~finite, NONFINITE, state.code)
        # Stalled: even at the smallest pseudo-time step no step of any length lowers the merit
        # (the flow direction is not a descent direction of |r|^2 where the Jacobian of a
        # non-conservative scene is far from symmetric, or round-off rules at a floor). The
        # forced shortest steps do not move the iterate: stop, so that a retry can start, instead
        # of creeping to the step limit while the other rows of a batch wait.
        stalled = tiny_dt & (~ok | ~accept)
        code = jnp.where(stalled & (code == SUCCESSFUL), STALLED, code)
        return PTCState(
            residual=keep(new.residual, state.residual),
            merit=keep(new.merit, state.merit),
            jacobian=jac,
            weights=new.weights,
            dt=dt,
            step=state.step + 1,
            escapes=state.escapes + escape.astype(state.escapes.dtype),
            # A non-conservative problem has no energy that the escape lowered: the
            # continuation may return to the same point, an attractor of the flow whose
            # symmetric stiffness is indefinite. There the flag lasts one step (no termination
            # on the escaped iterate itself); it used to hold such a row to the step limit.
            escaping=(escape | (state.escaping & self.symmetric)) & (eig < -self.stability_tol),
            leaving=jnp.where(
                eig < -self.stability_tol,
                jnp.where(escape, _LEAVING_STEPS, jnp.maximum(state.leaving - 1, 0)),
                0,
            ),
            eig=eig,
            eigvals=eigvals,
            eigvecs=eigvecs,
            escape_dy=escape_dy,
            drive=keep(new.drive, state.drive),
            code=code,
            # (tried again from the new point by ``step``)
            ahead_y=state.ahead_y,
            ahead_residual=state.ahead_residual,
            ahead_merit=state.ahead_merit,
            ahead_size=state.ahead_size,
            ahead_plain=state.ahead_plain,
        )

    def _next_dt(self, state: PTCState, r_new, alpha, accept, first, escape, eig):
        """The pseudo-time step for the next iteration (switched evolution relaxation).

        After an accepted full step ``dt`` grows by the fall of the residual (within
        ``_DT_GROWTH``, up to ``max_dt``); after an accepted shortened step it stays; after a
        rejected one it shrinks tenfold; on an escape it restarts at ``initial_dt``, and on the
        first step too, unless ``newton_start`` holds and the stiffness ``eig`` there is
        positive: then ``max_dt`` (Newton), until a step is shortened or rejected, when it
        restarts at ``initial_dt``.
        """
        dtype = state.dt.dtype
        ratio = max_abs(state.residual) / jnp.maximum(max_abs(r_new), jnp.finfo(dtype).tiny)
        full = accept & (alpha == 1.0)
        grown = jnp.minimum(state.dt * jnp.clip(ratio, *_DT_GROWTH), self.max_dt)
        start, newton_ended = self.initial_dt, jnp.asarray(False)
        if self.newton_start and self.symmetric:
            start = jnp.where(eig > self.stability_tol, self.max_dt, self.initial_dt)
            newton_ended = (state.dt >= self.max_dt) & ~full
        return jnp.where(
            first,
            start,
            jnp.where(
                escape | newton_ended,
                self.initial_dt,
                jnp.where(full, grown, jnp.where(accept, state.dt, 0.1 * state.dt)),
            ),
        ).astype(dtype)

    def terminate(self, fn, y, args, options, state: PTCState, tags):
        del fn, y, args, options, tags
        # After an escape the iterate is still near the saddle, and at a loose tolerance its
        # residual can already be below it (float32 at 1e-4: a saddle with eigenvalue -3e-4
        # left by 0.05 has a residual ~1.5e-5). It must first reach a stable point: the
        # saddle-free steps move it away from the saddle geometrically, and the energy, which
        # the escape lowered below the saddle's, cannot bring it back.
        converged = self._converged(state.residual) | self._ahead_done(state)
        done = converged & ~self._wants_escape(state) & ~state.escaping
        failed = state.code != SUCCESSFUL
        result = optx.RESULTS.where(
            failed, optx.RESULTS.nonlinear_divergence, optx.RESULTS.successful
        )
        return done | failed, result

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        del fn, args, options, tags, result
        return self.finish(y, state)[0], aux, {}
