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
one is made (one pass a column, from ``F0``), then the two stages'. Passes with nothing to do
are skipped, so a step with a held Jacobian runs two vector fields, and the program holds one
copy.

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

    def __check_init__(self):
        if isinstance(self.jacobian, str) and self.jacobian != "differences":
            raise ValueError(
                f'Rosenbrock23.jacobian must be callable, None or "differences", '
                f"got {self.jacobian!r}"
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
        shape = jax.eval_shape(terms.vf, t0, y0, args)
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

        h = t1 - t0
        differences = self.jacobian == "differences"
        if self.reuse == 1:
            f0_tree, held, age, fresh = solver_state, None, None, True
            # ``known is True`` resolves when traced: no start's vector field in the loop.
            known = True if made_jump is False else ~jnp.asarray(made_jump)
            jac = None if differences else self._given_jacobian(t0, y0, args, f)
        else:
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
                jac = jax.lax.cond(
                    fresh, lambda: self._given_jacobian(t0, y0, args, f), lambda: held
                )
            age = jnp.where(fresh, 0, age) + 1
        if jac is None:
            jac = jnp.zeros((x0.size, x0.size), x0.dtype)
        # Neither W nor T carry gradients: the step's derivative is that of the method with W
        # held fixed, a W-method's own (diffrax's implicit solvers stop them the same way).
        jac = jax.lax.stop_gradient(jac)
        if self.autonomous:
            rate = jnp.zeros_like(x0)
        else:
            rate = jax.jvp(lambda t: f(t, x0), (t0,), (jnp.ones_like(t0),))[1]
            rate = jax.lax.stop_gradient(rate)
        hdt = (h * _D) * rate
        f0_known = ravel_pytree(f0_tree)[0]
        columns = x0.size if differences else 0
        steps = difference_steps(x0)
        eye = jnp.eye(x0.size, dtype=x0.dtype)

        # Every vector field of a step is one pass of one loop, so that the compiled program
        # holds one copy of the vector field (XLA compiles each copy anew): the start's where
        # it is not known (the first step, after a jump), the Jacobian's differences where one
        # is made, then the two stages'. A pass makes its point, evaluates the vector field
        # there, and takes what it gives; a pass with nothing to do is skipped. ``lu`` is
        # ``W``'s factorisation, made before the first stage.
        def point(phase, i, c):
            def start(c):
                return t0, x0, c

            def difference(c):
                return t0, x0.at[i - 1].add(steps[i - 1]), c

            def first_stage(c):
                lu = jax.scipy.linalg.lu_factor(eye - (h * _D) * c["jac"])
                k1 = jax.scipy.linalg.lu_solve(lu, c["f0"] + hdt)
                return t0 + 0.5 * h, x0 + (0.5 * h) * k1, dict(c, lu=lu, k1=k1)

            def second_stage(c):
                k2 = jax.scipy.linalg.lu_solve(c["lu"], c["f1"] - c["k1"]) + c["k1"]
                return t1, x0 + h * k2, dict(c, k2=k2)

            return jax.lax.switch(phase, [start, difference, first_stage, second_stage], c)

        def take(phase, i, fx, c):
            def start(c):
                return dict(c, f0=jnp.where(known, c["f0"], fx))

            def difference(c):
                column = jax.lax.stop_gradient((fx - c["f0"]) / steps[i - 1])
                return dict(c, jac=c["jac"].at[:, i - 1].set(column))

            def first_stage(c):
                return dict(c, f1=fx)

            def second_stage(c):
                rhs = fx - _E32 * (c["k2"] - c["f1"]) - 2.0 * (c["k1"] - c["f0"]) + hdt
                return dict(c, f2=fx, k3=jax.scipy.linalg.lu_solve(c["lu"], rhs))

            return jax.lax.switch(phase, [start, difference, first_stage, second_stage], c)

        def one_pass(c, i):
            phase = jnp.select([i == 0, i <= columns, i == columns + 1], [0, 1, 2], 3)
            needed = jnp.select(
                [i == 0, i <= columns],
                [jnp.asarray(False) if known is True else eqxi.unvmap_any(~known), fresh],
                True,
            )

            def evaluate(c):
                t, x, c = point(phase, i, c)
                return take(phase, i, f(t, x), c)

            return jax.lax.cond(needed, evaluate, lambda c: c, c), None

        zero = jnp.zeros_like(x0)
        lu = (jnp.zeros_like(eye), jnp.zeros(x0.size, jnp.int32))
        carry = dict(f0=f0_known, jac=jac, lu=lu, k1=zero, k2=zero, f1=zero, f2=zero, k3=zero)
        passes = jnp.arange(1 if known is True else 0, columns + 3)
        c, _ = jax.lax.scan(one_pass, carry, passes)
        f0, k1, k2, k3, f2 = c["f0"], c["k1"], c["k2"], c["k3"], c["f2"]
        x1 = x0 + h * k2
        f2_tree = unravel(f2)
        error = unravel((h / 6.0) * (k1 - 2.0 * k2 + k3))
        if self.error_weight is not None:
            weight = jax.lax.stop_gradient(self.error_weight(y0, args))
            error = jax.tree.map(jnp.multiply, error, weight)
        y1 = unravel(x1)
        dense_info = dict(y0=y0, y1=y1, k0=unravel(h * f0), k1=unravel(h * f2))
        if held is None:
            return y1, error, dense_info, f2_tree, diffrax.RESULTS.successful
        jac = c["jac"]
        if self.secant:
            jac = secant_update(jac, x1 - x0, f2 - f0)
        state = (f2_tree, jac, age, jnp.asarray(True))
        return y1, error, dense_info, state, diffrax.RESULTS.successful


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
