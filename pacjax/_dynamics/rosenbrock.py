"""A linearly implicit (Rosenbrock-W) solver for diffrax: Shampine and Reichelt's ode23s.

diffrax's stiff solvers are implicit Runge-Kutta methods: every stage is a nonlinear solve,
several vector-field evaluations each, and the Jacobian they linearise with is the exact one of
the whole vector field. On pacjax's dynamics that Jacobian costs about fifteen vector fields
(its mass matrix and Coriolis forces are derivatives of the kinematics already), and each step
needs several more for its stages. A Rosenbrock method solves one linear system per stage
instead, with a matrix ``W = I - h d J`` factorised once per step; as a W-method (Steihaug and
Wolfbrandt) ode23s keeps its order with any ``J``, so ``J`` may leave out what is expensive and
not stiff (the derivatives of the mass matrix and of the Coriolis forces): only its stability
relies on ``J`` holding the stiff part. Per step: one ``J``, one LU factorisation, two new
vector fields (the third is the next step's first), three triangular solves.

The method (L. F. Shampine, M. W. Reichelt, "The MATLAB ODE suite", SIAM J. Sci. Comput. 18(1),
1997), ``d = 1 / (2 + sqrt 2)``, ``T = df/dt``:

    F0 = f(t0, y0)                          k1 = W^-1 (F0 + h d T)
    F1 = f(t0 + h/2, y0 + h/2 k1)           k2 = W^-1 (F1 - k1) + k1
    y1 = y0 + h k2                          F2 = f(t1, y1)
    k3 = W^-1 (F2 - (6 + sqrt 2)(k2 - F1) - 2 (k1 - F0) + h d T)
    error = h / 6 (k1 - 2 k2 + k3)

Second order, L-stable; dense output is the cubic Hermite interpolant of ``y0, y1, F0, F2``.

The error estimate is of third order with the exact Jacobian and of second with a stand-in, so
the step shrinks faster with the tolerance than a second-order method's must. It suits the
moderate tolerances (1e-3 to 1e-5) of control and learning; for tight ones an implicit
Runge-Kutta method of higher order takes fewer steps.

A W-method's order holding with any ``J`` also lets one ``J`` serve several steps, as stiff codes
(CVODE, RADAU5) hold theirs: with ``reuse > 1`` the Jacobian is made at the start of a step
only after ``reuse`` accepted steps with the last one (or after a jump), and is carried in the
solver state meanwhile. On one trajectory that makes an exact Jacobian (dear: one vector field
per state coordinate) affordable. Under ``vmap`` the rows make their Jacobians together: when
any row still stepping needs one, every row makes one and restarts its count (a choice by each
row's own flag would be a ``vmap``-ped select, which makes it every step). A row then takes
slightly different steps than alone, never fewer fresh Jacobians.

XLA compiles each copy of the vector field in a program anew, and on pacjax's dynamics each
copy is several seconds of a first simulation's compile time. A step therefore evaluates every
vector field it needs in one loop, one pass each: ``F0`` where it is not known (the first step,
after a jump; under ``vmap`` when any row needs it), the Jacobian's forward differences where
one is made (one pass a column, from ``F0``), then the two stages'. The program holds one
copy, and the loop makes only the passes needed: a step with a held Jacobian makes two. How it
loops depends on how it is differentiated (``Rosenbrock23.loop``): in reverse mode it is
equinox's checkpointed while loop, in forward mode a plain one (which reverse mode cannot
differentiate, and the checkpointed one forward mode cannot), and under an adjoint that needs
both a scan over every pass with the idle ones skipped by a ``cond``; a held-Jacobian step then
still visits the twenty-odd idle passes, about a third of its time.

A held ``J`` ages as the state moves, and the error estimate feels it: with ``J`` not the
Jacobian the estimate's leading term is of second order, ``(J - df/dy)`` applied along the
motion, so a stale ``J`` shrinks the steps. After each accepted step the held ``J`` therefore
takes Broyden's rank-one correction,

    J <- J + (dF - J dy) dy^T / (dy^T dy),   dy = y1 - y0,  dF = F2 - F0,

which makes it map the step just taken to the change of the vector field along it: exact, to
first order, in the direction the next step takes, the one the error estimate weighs. It costs
an outer product of vectors the step has already; the rows of ``qdot`` (zero and identity) are
left as they are, since they map every step exactly. A fresh ``J`` is still made every
``reuse`` steps: the correction fixes one direction a step, and a ``J`` that only takes
corrections drifts in the others.
"""

import math
from collections.abc import Callable
from typing import ClassVar

import diffrax
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

_D = 1.0 / (2.0 + math.sqrt(2.0))
_E32 = 6.0 + math.sqrt(2.0)


class Rosenbrock23(diffrax.AbstractAdaptiveSolver):
    """Shampine and Reichelt's ode23s, a Rosenbrock-W method (see the module).

    Attributes:
        jacobian: ``(t, y, args) -> J``, the ``(n, n)`` Jacobian (or a W-method's stand-in for
            it) of the vector field along the flattened state (``jax.flatten_util.ravel_pytree``
            order). None: the exact one, by forward-mode differentiation of the vector field.
            ``"differences"``: the exact one by forward differences, one vector field per state
            coordinate (steps: :func:`difference_steps`), in the step's loop of vector fields.
        autonomous: the vector field does not depend on ``t`` (constant controls), so ``T`` is
            zero. Its forward derivative in ``t`` is then left out: it traced the whole vector
            field once more per step.
        reuse: accepted steps one Jacobian serves (1: a new one every step; see the module).
        secant: with ``reuse > 1``, the held Jacobian takes Broyden's rank-one correction along
            each accepted step (see the module).
        error_weight: ``(y, args) -> w``, a pytree like ``y``: the error estimate is multiplied
            by ``w`` before the step-size controller scales it, so that a coordinate whose error
            moves the body less than its size suggests (the plane angle of a nearly straight
            segment, :func:`pacjax._dynamics.equations.plane_angle_weights`) is held less
            tightly. None: every coordinate as it is.
        loop: the step's loop of vector fields (see the module): ``"checkpointed"`` makes
            only the passes needed and is reverse-mode differentiable
            (``equinox.internal.while_loop``; diffrax's ``RecursiveCheckpointAdjoint``), not
            forward-mode; ``"lax"`` the same passes, forward-mode only (``ForwardMode``);
            ``"scan"`` visits every pass, skipping the idle ones, either mode.
            :func:`pacjax.simulate` sets it from its adjoint.
    """

    term_structure: ClassVar = diffrax.AbstractTerm
    interpolation_cls: ClassVar[Callable[..., diffrax.ThirdOrderHermitePolynomialInterpolation]] = (
        diffrax.ThirdOrderHermitePolynomialInterpolation
    )
    jacobian: Callable | str | None = eqx.field(static=True, default=None)
    autonomous: bool = eqx.field(static=True, default=False)
    reuse: int = eqx.field(static=True, default=1)
    secant: bool = eqx.field(static=True, default=True)
    error_weight: Callable | None = eqx.field(static=True, default=None)
    loop: str = eqx.field(static=True, default="checkpointed")

    def __check_init__(self):
        if isinstance(self.jacobian, str) and self.jacobian != "differences":
            raise ValueError(
                f'Rosenbrock23.jacobian must be callable, None or "differences", '
                f"got {self.jacobian!r}"
            )
        if self.loop not in ("checkpointed", "lax", "scan"):
            raise ValueError(
                f'Rosenbrock23.loop must be "checkpointed", "lax" or "scan", got {self.loop!r}'
            )
        if not (isinstance(self.reuse, int) and self.reuse >= 1):
            raise ValueError(f"Rosenbrock23.reuse must be an integer >= 1, got {self.reuse!r}")

    def order(self, terms):
        return 2

    def error_order(self, terms):
        return 3

    def init(self, terms, t0, t1, y0, args):
        # First same as last: the solver state is the vector field at the current state, and
        # with reuse the Jacobian held, the accepted steps it has served (``reuse`` now: the
        # first step makes one) and whether that vector field is known yet. With reuse it is
        # not: the first step evaluates it in its loop of stages (see ``step``), where a copy
        # here would be one more copy of the vector field for XLA to compile.
        if self.reuse == 1:
            return terms.vf(t0, y0, args)
        x0, _ = ravel_pytree(y0)
        # equinox's, not jax's: jax's makes every leaf of ``args`` abstract, and a jitted vector
        # field would be traced anew for it (its Python scalars are static to the jit).
        shape = eqx.filter_eval_shape(terms.vf, t0, y0, args)
        f0 = jax.tree.map(lambda leaf: jnp.zeros(leaf.shape, leaf.dtype), shape)
        held = jnp.zeros((x0.size, x0.size), x0.dtype)
        return f0, held, jnp.asarray(self.reuse, jnp.int32), jnp.asarray(False)

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def _given_jacobian(self, t, y, args, f):
        """The Jacobian at ``(t, y)`` where it is not made by differences (those are columns
        of the step's loop of vector fields)."""
        if self.jacobian is None:
            x, _ = ravel_pytree(y)
            return jax.jacfwd(lambda z: f(t, z))(x)
        return self.jacobian(t, y, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        x0, unravel = ravel_pytree(y0)

        def f(t, x):
            return ravel_pytree(terms.vf(t, unravel(x), args))[0]

        f0_tree, jac, age, known, fresh = self._start(f, t0, t1, y0, args, solver_state, made_jump)
        # Neither W nor T carry gradients: the step's derivative is that of the method with W
        # held fixed, a W-method's own (diffrax's implicit solvers stop them the same way).
        jac = jax.lax.stop_gradient(jac)
        if self.autonomous:
            rate = jnp.zeros_like(x0)
        else:
            rate = jax.jvp(lambda t: f(t, x0), (t0,), (jnp.ones_like(t0),))[1]
            rate = jax.lax.stop_gradient(rate)
        h = t1 - t0
        columns = x0.size if self.jacobian == "differences" else 0
        passes = _Passes(f, t0, t1, x0, h * _D * rate, columns, known, fresh)
        c = passes.run(ravel_pytree(f0_tree)[0], jac, self.loop)
        f0, k1, k2, k3, f2 = c["f0"], c["k1"], c["k2"], c["k3"], c["f2"]
        x1 = x0 + h * k2
        error = unravel((h / 6.0) * (k1 - 2.0 * k2 + k3))
        if self.error_weight is not None:
            weight = jax.lax.stop_gradient(self.error_weight(y0, args))
            error = jax.tree.map(jnp.multiply, error, weight)
        y1 = unravel(x1)
        dense_info = dict(y0=y0, y1=y1, k0=unravel(h * f0), k1=unravel(h * f2))
        if age is None:
            return y1, error, dense_info, unravel(f2), diffrax.RESULTS.successful
        jac = c["jac"]
        if self.secant:
            jac = secant_update(jac, x1 - x0, f2 - f0)
        state = (unravel(f2), jac, age, jnp.asarray(True))
        return y1, error, dense_info, state, diffrax.RESULTS.successful

    def _start(self, f, t0, t1, y0, args, solver_state, made_jump):
        """What a step starts from: the start's vector field (as held; a pytree like ``y0``),
        the Jacobian (the held one where differences will replace it), the accepted steps it
        will have served after this one (None without reuse), whether the start's vector field
        is known (``True`` when that is known at trace time) and whether a Jacobian is made
        (unbatched)."""
        x0, _ = ravel_pytree(y0)
        differences = self.jacobian == "differences"
        if self.reuse == 1:
            # ``known is True`` resolves when traced: no start's vector field in the loop.
            known = True if made_jump is False else ~jnp.asarray(made_jump)
            if differences:
                jac = jnp.zeros((x0.size, x0.size), x0.dtype)
            else:
                jac = self._given_jacobian(t0, y0, args, f)
            return solver_state, jac, None, known, True
        f0_tree, held, age, known = solver_state
        known = known & ~jnp.asarray(made_jump)
        fresh = (age >= self.reuse) | jnp.asarray(made_jump)
        # Under vmap the rows make their Jacobians together, when any row still stepping
        # needs one (a finished row steps from its end to its end): a choice by each row's
        # own flag would be a select, both sides every step.
        fresh = eqxi.unvmap_any(fresh & (t1 > t0))
        if differences:
            jac = held
        else:
            jac = jax.lax.cond(fresh, lambda: self._given_jacobian(t0, y0, args, f), lambda: held)
        return f0_tree, jac, jnp.where(fresh, 0, age) + 1, known, fresh


class _Passes:
    """A step's loop of vector fields (see the module): pass 0 evaluates the start's, passes
    ``1..columns`` the Jacobian's forward differences (one column each), pass ``columns + 1``
    the first stage's and ``columns + 2`` the second's. A pass makes its point, evaluates the
    vector field there and takes what it gives into the loop's carry; ``lu`` is ``W``'s
    factorisation, made before the first stage.

    ``known``: whether the start's vector field is known (``True`` when that is known at trace
    time: no pass 0); ``fresh``: whether a Jacobian is made (unbatched, as ``known``'s use is:
    under ``vmap`` every row makes the passes any row needs, so the loop's index stays
    unbatched and each pass evaluates one vector field, not every branch's)."""

    def __init__(self, f, t0, t1, x0, hdt, columns: int, known, fresh):
        self.f, self.t0, self.t1, self.x0, self.hdt = f, t0, t1, x0, hdt
        self.h = t1 - t0
        self.columns, self.known, self.fresh = columns, known, jnp.asarray(fresh)
        self.steps = difference_steps(x0)
        self.eye = jnp.eye(x0.size, dtype=x0.dtype)

    def run(self, f0, jac, loop: str) -> dict:
        """The carry after every pass needed (``loop``: :class:`Rosenbrock23`'s)."""
        zero = jnp.zeros_like(self.x0)
        lu = (jnp.zeros_like(self.eye), jnp.zeros(self.x0.size, jnp.int32))
        carry = dict(f0=f0, jac=jac, lu=lu, k1=zero, k2=zero, f1=zero, f2=zero, k3=zero)
        end = self.columns + 3
        if loop == "scan":
            # Every pass visited, the idle ones skipped by a cond: differentiable either way.
            def scan_pass(c, i):
                return jax.lax.cond(self.needed(i), lambda c: self.one(c, i), lambda c: c, c), None

            first = 1 if self.known is True else 0
            return jax.lax.scan(scan_pass, carry, jnp.arange(first, end))[0]
        first = jnp.where(self.needed(0), 0, self.following(0))
        _, c = eqxi.while_loop(
            lambda ic: ic[0] < end,
            lambda ic: (self.following(ic[0]), self.one(ic[1], ic[0])),
            (first, carry),
            max_steps=end,
            checkpoints=end,
            kind=loop,
        )
        return c

    def needed(self, i):
        """Whether pass ``i`` has something to do."""
        start = jnp.asarray(False) if self.known is True else eqxi.unvmap_any(~self.known)
        return jnp.select([i == 0, i <= self.columns], [start, self.fresh], True)

    def following(self, i):
        """The pass needed after pass ``i``: the next, past the differences where no
        Jacobian is made."""
        return jnp.where((i + 1 <= self.columns) & ~self.fresh, self.columns + 1, i + 1)

    def one(self, c, i):
        phase = jnp.select([i == 0, i <= self.columns, i == self.columns + 1], [0, 1, 2], 3)
        t, x, c = jax.lax.switch(phase, self._points, i, c)
        return jax.lax.switch(phase, self._takes, i, self.f(t, x), c)

    @property
    def _points(self):
        """Per phase: ``(i, c) -> (t, x, c)``, where pass ``i`` evaluates."""
        t0, x0, h = self.t0, self.x0, self.h

        def start(i, c):
            return t0, x0, c

        def difference(i, c):
            return t0, x0.at[i - 1].add(self.steps[i - 1]), c

        def first_stage(i, c):
            lu = jax.scipy.linalg.lu_factor(self.eye - (h * _D) * c["jac"])
            k1 = jax.scipy.linalg.lu_solve(lu, c["f0"] + self.hdt)
            return t0 + 0.5 * h, x0 + (0.5 * h) * k1, dict(c, lu=lu, k1=k1)

        def second_stage(i, c):
            k2 = jax.scipy.linalg.lu_solve(c["lu"], c["f1"] - c["k1"]) + c["k1"]
            return self.t1, x0 + h * k2, dict(c, k2=k2)

        return [start, difference, first_stage, second_stage]

    @property
    def _takes(self):
        """Per phase: ``(i, fx, c) -> c``, what pass ``i`` takes from its vector field."""

        def start(i, fx, c):
            return dict(c, f0=jnp.where(self.known, c["f0"], fx))

        def difference(i, fx, c):
            column = jax.lax.stop_gradient((fx - c["f0"]) / self.steps[i - 1])
            return dict(c, jac=c["jac"].at[:, i - 1].set(column))

        def first_stage(i, fx, c):
            return dict(c, f1=fx)

        def second_stage(i, fx, c):
            rhs = fx - _E32 * (c["k2"] - c["f1"]) - 2.0 * (c["k1"] - c["f0"]) + self.hdt
            return dict(c, f2=fx, k3=jax.scipy.linalg.lu_solve(c["lu"], rhs))

        return [start, difference, first_stage, second_stage]


def secant_update(jac, dy, df):
    """Broyden's rank-one correction of ``jac`` to map ``dy`` to ``df`` (none for ``dy = 0``);
    held fixed under differentiation, as ``W`` is."""
    dy, df = jax.lax.stop_gradient((dy, df))
    norm = jnp.dot(dy, dy)
    return jac + jnp.outer(df - jac @ dy, dy / jnp.where(norm > 0, norm, 1.0))


def difference_steps(x: jax.Array) -> jax.Array:
    """The forward differences' step in each coordinate of ``x``: the square root of the
    machine epsilon times its size (at least one), so that the truncation is about that relative
    to the Jacobian's entries; a W-method does not feel it."""
    return jax.lax.stop_gradient(jnp.sqrt(jnp.finfo(x.dtype).eps) * jnp.maximum(jnp.abs(x), 1.0))
