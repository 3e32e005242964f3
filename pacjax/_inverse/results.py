"""Results of inverse statics: :class:`InverseResult`, :class:`Tracking`, :class:`Workspace`.

See :mod:`pacjax.inverse`.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .. import _deprecated
from .._results import RESULTS, code_of, describe, from_code

#: The integer codes of :attr:`InverseResult.code` (deprecated: use :attr:`InverseResult.result`).
REACHED = 0
NOT_REACHED = 1
NO_EQUILIBRIUM = 2
#: Each code's message (deprecated with the codes).
MESSAGES = {
    REACHED: "target reached",
    NOT_REACHED: RESULTS[RESULTS.target_not_reached],
    NO_EQUILIBRIUM: RESULTS[RESULTS.no_equilibrium],
}


def inverse_result(reached, converged) -> RESULTS:
    """``successful`` where the target is reached, ``target_not_reached`` where the pose at
    the best commands is a converged, stable equilibrium, else ``no_equilibrium``."""
    codes = np.where(
        np.asarray(reached),
        code_of(RESULTS.successful),
        np.where(
            np.asarray(converged),
            code_of(RESULTS.target_not_reached),
            code_of(RESULTS.no_equilibrium),
        ),
    )
    return from_code(codes)


class InverseResult(eqx.Module):
    """Commands that reach a target, and the pose they reach (leading batch axis when batched).

    Attributes:
        controls: (n_tendons,) commands (m pull-in, or N tension).
        q: (n_dofs,) the equilibrium under ``controls``.
        error: (m) position error: distance from the tip to the target, or the largest
            distance from a marker site to its target (inf when no start gave a converged,
            stable equilibrium).
        orientation_error: (rad) angle between the reached and the target tip orientation
            (0 for position targets).
        reached: ``error <= reached_tol`` (and the orientation within ``orientation_tol``) at a
            converged, stable equilibrium.
        position: (3,) reached tip position (m).
        rotation: (3, 3) reached tip orientation.
        tensions: (n_tendons,) tendon tensions (N) at the solution.
        iterations: Levenberg-Marquardt iterations, all starts together.
        starts: how many starts were used.
        converged: the equilibrium at the solution converged and is stable.
        result: a :class:`pacjax.RESULTS` item: ``successful`` (reached),
            ``target_not_reached`` (the closest pose found) or ``no_equilibrium``; see
            :attr:`message`.
    """

    controls: Float[Array, "*batch n_tendons"]
    q: Float[Array, "*batch n_dofs"]
    error: Float[Array, "*batch"]
    orientation_error: Float[Array, "*batch"]
    reached: Bool[Array, "*batch"]
    position: Float[Array, "*batch 3"]
    rotation: Float[Array, "*batch 3 3"]
    tensions: Float[Array, "*batch n_tendons"]
    iterations: Int[Array, "*batch"]
    starts: Int[Array, "*batch"]
    converged: Bool[Array, "*batch"]
    result: RESULTS

    @property
    def successful(self) -> Bool[Array, "*batch"]:
        """``result == RESULTS.successful``: the target was reached."""
        return self.result == RESULTS.successful

    @property
    def message(self) -> str | list[str]:
        """What happened, in words (a list for a batch)."""
        return describe(self.result, "target reached")

    @property
    def code(self) -> Int[Array, "*batch"]:
        """Deprecated: 0 reached, 1 not reached, 2 no equilibrium; use :attr:`result`."""
        _deprecated.warn("InverseResult.code", "InverseResult.result (pacjax.RESULTS)")
        codes = np.select(
            [
                np.asarray(self.result == RESULTS.successful),
                np.asarray(self.result == RESULTS.target_not_reached),
            ],
            [REACHED, NOT_REACHED],
            NO_EQUILIBRIUM,
        )
        return jnp.asarray(codes)


class Tracking(eqx.Module):
    """A tracked path: an :class:`InverseResult` per waypoint, and how smooth and fast it was.

    Attributes:
        waypoints: :class:`InverseResult` with a leading waypoint axis.
        max_command_jump: largest change of any command between neighbouring waypoints (m, or N
            for tension-mode tendons).
        seconds: wall-clock time of the whole path (compilation excluded when warm).
        waypoints_per_second: ``len(path) / seconds``.
    """

    waypoints: InverseResult
    max_command_jump: float = eqx.field(static=True)
    seconds: float = eqx.field(static=True)
    waypoints_per_second: float = eqx.field(static=True)

    @property
    def result(self) -> RESULTS:
        """How each waypoint's solve ended (a :class:`pacjax.RESULTS` item per waypoint)."""
        return self.waypoints.result

    @property
    def successful(self) -> Bool[Array, " waypoints"]:
        """Whether each waypoint was reached."""
        return self.waypoints.successful


class Workspace(eqx.Module):
    """Forward-solved samples of the commands' range: the reachable tip positions, and good
    starts for inverse solves (the nearest sample to a target).

    Attributes:
        controls: (n, n_tendons) sampled commands.
        q: (n, n_dofs) their equilibria.
        tip: (n, 3) tip positions (m).
        converged: (n,) converged, stable equilibria (only those are used as starts).
    """

    controls: Float[Array, "n n_tendons"]
    q: Float[Array, "n n_dofs"]
    tip: Float[Array, "n 3"]
    converged: Bool[Array, " n"]

    def nearest(self, position, k: int = 1) -> np.ndarray:
        """Indices of the ``k`` converged samples whose tips are closest to ``position``."""
        tip = np.asarray(self.tip)
        d = np.linalg.norm(tip - np.asarray(position, float)[..., None, :], axis=-1)
        d = np.where(np.asarray(self.converged), d, np.inf)
        return np.argsort(d, axis=-1)[..., :k]
