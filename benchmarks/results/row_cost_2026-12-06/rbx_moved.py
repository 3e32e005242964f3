LOG = None
import numpy as _np
IDX = _np.array([2, 6, 10])
DPHI = 1e9
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
slightly different steps than alone, never fewer fresh Jacobians. With reuse the first step also
evaluates ``F0`` itself, in the loop that evaluates its stages (the compiled program then holds
two copies of the vector field, the stages' and the differences', not three: XLA compiles each
copy anew); under ``vmap`` it is made when any row needs it.

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


class Rosenbrock23X(diffrax.AbstractAdaptiveSolver):
    """Shampine and Reichelt's ode23s, a Rosenbrock-W method (see the module).

    Attributes:
        jacobian: ``(t, y, args) -> J``, the ``(n, n)`` Jacobian (or a W-method's stand-in for
            it) of the vector field along the flattened state (``jax.flatten_util.ravel_pytree``
            order). None: the exact one, by forward-mode differentiation of the vector field.
            ``"differences"``: the exact one by forward differences
            (:func:`forward_differences`), one vector field per state coordinate.
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
        return f0, held, jnp.asarray(self.reuse, jnp.int32), jnp.asarray(False), x0, jnp.asarray(0, jnp.int32)

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def _jacobian(self, t, y, args, f, f0):
        """The Jacobian at ``(t, y)``; ``f0`` the vector field there, or None where it is not
        known yet (differences then evaluate it too)."""
        x, _ = ravel_pytree(y)
        if self.jacobian is None:
            return jax.jacfwd(lambda z: f(t, z))(x)
        if self.jacobian == "differences":
            return forward_differences(lambda z: f(t, z), x, f0)
        return self.jacobian(t, y, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        x0, unravel = ravel_pytree(y0)

        def f(t, x):
            return ravel_pytree(terms.vf(t, unravel(x), args))[0]

        h = t1 - t0
        if self.reuse == 1:
            f0_tree, held, age, known = solver_state, None, None, True
            if made_jump is not False:  # resolved when traced: no second copy of the vector field
                f0_tree = jax.lax.cond(made_jump, lambda: terms.vf(t0, y0, args), lambda: f0_tree)
            jac = self._jacobian(t0, y0, args, f, ravel_pytree(f0_tree)[0])
        else:
            # The vector field at the start is evaluated in the loop of stages below where it
            # is not known (the first step, after a jump), so that the program holds no copy of
            # it outside the step; the differences evaluate it for themselves.
            f0_tree, held, age, known, xj, nj = solver_state
            dist = jnp.max(jnp.abs(x0 - xj)[IDX]); moved = dist > DPHI
            if LOG is not None: jax.debug.callback(lambda d, t: LOG.append((float(t), float(d))), dist, t0)
            known = known & ~jnp.asarray(made_jump)
            fresh = (age >= self.reuse) | jnp.asarray(made_jump) | moved
            # Under vmap the rows make their Jacobians together, when any row still stepping
            # needs one (a finished row steps from its end to its end): a choice by each row's
            # own flag would be a select, both sides every step.
            fresh = eqxi.unvmap_any(fresh & (t1 > t0))
            jac = jax.lax.cond(fresh, lambda: self._jacobian(t0, y0, args, f, None), lambda: held)
            age = jnp.where(fresh, 0, age) + 1
            nj = nj + fresh.astype(jnp.int32)
            xj = jnp.where(fresh, x0, xj)
        f0_known = ravel_pytree(f0_tree)[0]
        # Neither W nor T carry gradients: the step's derivative is that of the method with W
        # held fixed, a W-method's own (diffrax's implicit solvers stop them the same way).
        jac = jax.lax.stop_gradient(jac)
        if self.autonomous:
            rate = jnp.zeros_like(x0)
        else:
            rate = jax.jvp(lambda t: f(t, x0), (t0,), (jnp.ones_like(t0),))[1]
            rate = jax.lax.stop_gradient(rate)
        lu = jax.scipy.linalg.lu_factor(jnp.eye(x0.size, dtype=x0.dtype) - (h * _D) * jac)

        def solve(b):
            return jax.scipy.linalg.lu_solve(lu, b)

        hdt = (h * _D) * rate

        def stage(carry, i):
            # The vector fields of a step as one loop (the start's where it is not known, then
            # the two new ones), so that the compiled program holds one copy of the vector
            # field for them: XLA compiles each copy anew.
            f0, k1, k2, f1 = carry
            x = x0 + jnp.select([i == 1, i == 2], [(0.5 * h) * k1, h * k2], jnp.zeros_like(x0))
            t = t0 + jnp.select([i == 1, i == 2], [0.5 * h, h], 0.0 * h)
            if known is True:
                fx = f(t, x)
            else:
                need = (i > 0) | ~known
                fx = jax.lax.cond(eqxi.unvmap_any(need), lambda: f(t, x), lambda: f0_known)
                fx = jnp.where(need, fx, f0_known)
            f0 = jnp.where(i == 0, fx, f0)
            rhs = jnp.select(
                [i == 0, i == 1],
                [f0 + hdt, fx - k1],
                fx - _E32 * (k2 - f1) - 2.0 * (k1 - f0) + hdt,
            )
            k = solve(rhs)
            k1 = jnp.where(i == 0, k, k1)
            k2 = jnp.where(i == 1, k + k1, k2)
            f1 = jnp.where(i == 1, fx, f1)
            return (f0, k1, k2, f1), (k, fx)

        zero = jnp.zeros_like(x0)
        if known is True:  # first same as last: the start's vector field is the state's
            first = (f0_known, solve(f0_known + hdt), zero, zero)
            (f0, k1, k2, _), (ks, fs) = jax.lax.scan(stage, first, jnp.arange(1, 3))
        else:
            (f0, k1, k2, _), (ks, fs) = jax.lax.scan(stage, (zero,) * 4, jnp.arange(3))
        k3, f2 = ks[-1], fs[-1]
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
        if self.secant:
            jac = secant_update(jac, x1 - x0, f2 - f0)
        state = (f2_tree, jac, age, jnp.asarray(True), xj, nj)
        return y1, error, dense_info, state, diffrax.RESULTS.successful


def secant_update(jac, dy, df):
    """Broyden's rank-one correction of ``jac`` to map ``dy`` to ``df`` (none for ``dy = 0``);
    held fixed under differentiation, as ``W`` is."""
    dy, df = jax.lax.stop_gradient((dy, df))
    norm = jnp.dot(dy, dy)
    return jac + jnp.outer(df - jac @ dy, dy / jnp.where(norm > 0, norm, 1.0))


def forward_differences(f: Callable, x: jax.Array, fx: jax.Array | None = None) -> jax.Array:
    """The Jacobian of ``f`` at ``x`` (where it is ``fx``; None: evaluated here too, in the same
    loop) by forward differences, one coordinate at a time (a ``lax.map``: the program holds
    one more copy of ``f``, where ``jax.jacfwd`` traces its forward derivative, a larger program
    that compiles for longer).

    Each coordinate's step is the square root of the machine epsilon times its size (at
    least one), so the truncation is about that relative to the Jacobian's entries; a W-method
    does not feel it.
    """
    steps = jnp.sqrt(jnp.finfo(x.dtype).eps) * jnp.maximum(jnp.abs(x), 1.0)
    if fx is None:
        # Row 0 the unmoved point: f(x) from the loop's own copy of f.
        moved = jnp.concatenate([jnp.zeros((1, x.size), x.dtype), jnp.diag(steps)])
        values = jax.lax.map(lambda dx: f(x + dx), moved)
        return ((values[1:] - values[0]) / steps[:, None]).T

    def column(j):
        return (f(x.at[j].add(steps[j])) - fx) / steps[j]

    return jax.lax.map(column, jnp.arange(x.size)).T
