"""The chord root finder of pacjax's implicit Runge-Kutta solvers (``diffrax.Kvaerno5``).

``diffrax.VeryChord`` linearises the stage equation once per step with ``lineax.linearise`` (a
``jax.linearize`` of the vector field, materialised column by column when it is factorised).
On pacjax's vector fields, whose kinematics is thousands of primitives, tracing that
linearisation was two thirds of the time to trace a simulation. :class:`DenseChord` is the same
method with the Jacobian taken in one ``jax.jacfwd`` (``lineax.materialise`` of the Jacobian
operator): the same matrix, the same iterates and the same termination
(``diffrax.VeryChord``'s), traced and compiled in a fraction of the time (the figures are in
``benchmarks/RESULTS.md``, "Figures behind the solver's settings").
"""

import diffrax
import equinox as eqx
import jax
import lineax as lx


class _NoAux(eqx.Module):
    fn: object

    def __call__(self, y, args):
        return self.fn(y, args)[0]


class DenseChord(diffrax.VeryChord):
    """``diffrax.VeryChord`` with the Jacobian materialised by forward mode (see the module)."""

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        if "init_state" in options:
            return options["init_state"]
        jac = lx.materialise(lx.JacobianLinearOperator(_NoAux(fn), y, args, tags=tags, jac="fwd"))
        linear_state = self.linear_solver.init(jac, options={})
        dynamic, static = eqx.partition(linear_state, eqx.is_array)
        linear_state = eqx.combine(jax.lax.stop_gradient(dynamic), static)
        # The rest of the state is VeryChord's own: built from an identity map, which costs
        # nothing to linearise, with the linearisation then swapped for the Jacobian above.
        state = super().init(lambda x, _: (x, None), y, None, {}, f_struct, aux_struct, frozenset())
        return eqx.tree_at(lambda s: s.linear_state, state, (jac, linear_state))


def kvaerno5() -> diffrax.Kvaerno5:
    """``diffrax.Kvaerno5`` with :class:`DenseChord`, its tolerances those of the step-size
    controller (as diffrax's default root finder)."""
    return diffrax.Kvaerno5(root_finder=diffrax.with_stepsize_controller_tols(DenseChord)())
