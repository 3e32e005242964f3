"""Results of inverse statics: :class:`InverseResult`, :class:`Tracking`, :class:`Workspace`.

See :mod:`pacjax.inverse`.
"""

from __future__ import annotations

import equinox as eqx
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .._statics.solution import describe_codes

#: Result codes of an inverse solve.
REACHED = 0
NOT_REACHED = 1
NO_EQUILIBRIUM = 2
MESSAGES = {
    REACHED: "target reached",
    NOT_REACHED: "target not reached: the closest pose found is returned (out of reach, or "
    "blocked by the bounds and limits)",
    NO_EQUILIBRIUM: "no converged, stable equilibrium at the best commands found",
}


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
        code: 0 reached, 1 not reached (closest pose), 2 no equilibrium; see :attr:`message`.
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
    code: Int[Array, "*batch"]

    @property
    def message(self) -> str | list[str]:
        """What happened, in words (a list for a batch)."""
        return describe_codes(self.code, MESSAGES)


class Tracking(eqx.Module):
    """A tracked path: an :class:`InverseResult` per waypoint, and how smooth and fast it was.

    Attributes:
        result: :class:`InverseResult` with a leading waypoint axis.
        max_command_jump: largest change of any command between neighbouring waypoints (m, or N
            for tension-mode tendons).
        seconds: wall-clock time of the whole path (compilation excluded when warm).
        waypoints_per_second: ``len(path) / seconds``.
    """

    result: InverseResult
    max_command_jump: float = eqx.field(static=True)
    seconds: float = eqx.field(static=True)
    waypoints_per_second: float = eqx.field(static=True)


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
