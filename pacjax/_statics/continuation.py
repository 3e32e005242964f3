"""Retries for a failed equilibrium: load continuation (non-conservative loads switched on from
the equilibrium without them), order continuation (``PolynomialCurvature`` from the equilibrium
one order lower) and the diffrax flow, in that order (:func:`retry_failed`), for single and
batched solves alike: each passes its own ``solve``."""

import dataclasses

import equinox as eqx
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._model.loads import PointForce, PointMoment
from .._model.scene import Scene
from .._model.strain import PolynomialCurvature
from .solution import Equilibrium


def conservative_part(scene: Scene) -> Scene:
    """``scene`` without its non-conservative loads (follower forces, point moments).

    Its equilibrium (found by the saddle-free, energy-descending continuation) is a start from
    which continuation reaches the full one where a non-conservative solve from the straight
    configuration fails. (With the residual-norm merit used before the frozen-work merit of
    :class:`pacjax._statics.ptc.PseudoTransientContinuation`, the paper's robot with a 3.41 N tip
    follower force and random commands: from straight, 300 steps to a scaled residual ~0.1;
    from the equilibrium without the force, 10 steps.) In a batch, apply it after the per-row
    ``update``: load indices change.
    """

    def conservative(load):
        return not (
            isinstance(load, PointMoment) or (isinstance(load, PointForce) and load.follower)
        )

    kept = tuple(load for load in scene.loads if conservative(load))
    return eqx.tree_at(lambda sc: sc.loads, scene, kept)


def load_continuation(solve, q0) -> Equilibrium:
    """Load continuation for a non-conservative scene: ``solve(True, q0)`` solves its
    conservative part, ``solve(False, start)`` the full loads from that equilibrium (steps of
    both counted). Single solves and batch retries pass their own ``solve``."""
    start = solve(True, q0)
    eq = solve(False, np.asarray(start.q))
    return eqx.tree_at(lambda e: e.steps, eq, eq.steps + start.steps)


class OrderStep(eqx.Module):
    """The same scene with a ``PolynomialCurvature`` one order lower, and the exact maps between
    the two coordinate sets (the monomial bases are nested: a lower-order curvature is the
    higher-order one with a zero top coefficient)."""

    scene: Scene
    low: PolynomialCurvature = eqx.field(static=True)
    high: PolynomialCurvature = eqx.field(static=True)

    def _blocks(self, q, model):
        """``q`` (..., n_dofs) as (..., segments, components, order + 1) and the ``dL`` column."""
        per = q.reshape(q.shape[:-1] + (self.scene.n_segments, model.dofs_per_segment()))
        n = model.order + 1
        comps = per[..., :-1].reshape(per.shape[:-1] + ((per.shape[-1] - 1) // n, n))
        return comps, per[..., -1:]

    def embed(self, q_low: np.ndarray) -> np.ndarray:
        """Lower-order coordinates as this order's (same curvature, same configuration)."""
        comps, dl = self._blocks(np.asarray(q_low), self.low)
        comps = np.concatenate([comps, np.zeros(comps.shape[:-1] + (1,))], axis=-1)
        per = np.concatenate([comps.reshape(comps.shape[:-2] + (-1,)), dl], axis=-1)
        return per.reshape(per.shape[:-2] + (-1,))

    def truncate(self, q: np.ndarray) -> np.ndarray:
        """This order's coordinates with the top coefficient dropped (a start for the lower)."""
        comps, dl = self._blocks(np.asarray(q), self.high)
        per = np.concatenate([comps[..., :-1].reshape(comps.shape[:-2] + (-1,)), dl], axis=-1)
        return per.reshape(per.shape[:-2] + (-1,))


def order_step(scene: Scene) -> OrderStep | None:
    """An :class:`OrderStep` down from a ``PolynomialCurvature`` scene of order >= 2, else None.

    Its equilibrium, embedded, is a start from which the higher order converges where the
    straight start stalls: the paper's robot with ``PolynomialCurvature(3)`` under a 3.41 N tip
    follower force, one row of 24 (``random_commands(24, seed=1)[16]``), stalls from straight
    at a scaled residual of 1.4e-2 after 300 steps, load continuation included; from the
    ``PolynomialCurvature(2)`` equilibrium it converges in 17 steps.
    """
    model = scene.model
    if not isinstance(model, PolynomialCurvature) or model.order < 2:
        return None
    if scene.free_coordinates() is not None or scene.rest_coordinates() is not None:
        # Pinned coordinates or a rest curvature are written in this order's layout.
        return None
    low = PolynomialCurvature(model.order - 1, twist=model.twist)
    return OrderStep(eqx.tree_at(lambda sc: sc.model, scene, low), low, model)


def order_continuation(step: OrderStep, solve_low, solve, q0) -> Equilibrium:
    """``solve_low(start)`` solves the lower-order scene (with its own retries), ``solve(start)``
    this one from that equilibrium, embedded (steps of both counted)."""
    low = solve_low(step.truncate(q0))
    eq = solve(step.embed(np.asarray(low.q)))
    return eqx.tree_at(lambda e: e.steps, eq, eq.steps + low.steps)


def retry_failed(scene: Scene, eq: Equilibrium, starts, solve, options, flow: bool = True):
    """The rows of ``eq`` (a batch) that failed, solved again, each retry kept where it
    converged: for a non-conservative scene first by load continuation (from the equilibrium of
    its conservative part, :func:`conservative_part`), for ``PolynomialCurvature`` of order >= 2
    by order continuation (from the equilibrium one order lower, itself retried the same way
    without the flow, :func:`order_step`), then, with ``flow``, with the diffrax flow
    (``method="flow"``).

    ``solve(rows, starts, options, conservative=False, scene=scene)`` solves those rows of the
    batch (an index array) from ``starts`` (one per row), with the scene's conservative part
    when ``conservative``; ``starts`` (rows, n_dofs) are the rows' first starts.
    """

    def failed(eq):
        return np.flatnonzero(~np.asarray(eq.converged))

    bad = failed(eq)
    if bad.size and not scene.is_conservative:
        retry = load_continuation(lambda cons, start: solve(bad, start, options, cons), starts[bad])
        eq = _merge(eq, bad, retry)
    step = order_step(scene)
    bad = failed(eq)
    if step is not None and bad.size:

        def solve_low(start, bad=bad):
            def solve_subset(rows, s, o, conservative=False, scene=step.scene):
                return solve(bad[rows], s, o, conservative, scene)

            low = solve_subset(np.arange(bad.size), start, options)
            return retry_failed(step.scene, low, start, solve_subset, options, flow=False)

        retry = order_continuation(step, solve_low, lambda s: solve(bad, s, options), starts[bad])
        eq = _merge(eq, bad, retry)
    bad = failed(eq)
    if flow and bad.size:
        flow_options = dataclasses.replace(options, method="flow")
        eq = _merge(eq, bad, solve(bad, starts[bad], flow_options))
    return eq


def _merge(eq: Equilibrium, rows, retry: Equilibrium) -> Equilibrium:
    """``eq`` with its ``rows`` replaced by ``retry``'s where the retry converged."""
    better = np.asarray(retry.converged)
    if not better.any():
        return eq
    return jtu.tree_map(lambda a, b: jnp.asarray(a).at[rows[better]].set(b[better]), eq, retry)
