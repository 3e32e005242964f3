"""The result of an equilibrium solve: :class:`Equilibrium`."""

import equinox as eqx
from jaxtyping import Array, Bool, Float, Int

from .._results import RESULTS, describe


class Equilibrium(eqx.Module):
    """A static equilibrium (fields carry a leading batch axis from :func:`solve_batch`).

    Attributes:
        q: generalised coordinates, flat ``(n_segments * dofs_per_segment,)``.
        converged: whether the scaled residual fell below the tolerance.
        residual_norm: ``max_i |F_i| / (D_ii sigma_i)``, the residual in units of the elastic
            stiffness: the strain (rad, or relative elongation) that the elastic force alone
            would need to balance what is left. Dimensionless.
        stable: whether the smallest eigenvalue of the (scaled, symmetrised) stiffness at the
            equilibrium is above ``-stability_tol``: False at a saddle (buckled state, PAC's
            spurious straight saddle) or a maximum.
        min_hessian_eigenvalue: that smallest eigenvalue of ``D^-1/2 dF/dq D^-1/2`` (for a
            conservative scene, the Hessian of ``V``), relative to the elastic stiffness (1 means
            as stiff as the body alone).
        steps: continuation steps plus Newton polish steps, one linearisation each (the first
            at the start). A row of :func:`pacjax.solve_batch` whose last step lands within the
            tolerance ends there with a residual evaluation, not a step of its own.
        result: how the solve ended, a :class:`pacjax.RESULTS` item (see :attr:`reason`):
            ``successful`` exactly when ``converged`` and ``stable``; ``converged_saddle`` for
            a converged unstable equilibrium (read ``converged`` for any stationary point).
        energy: potential energy (J) at ``q`` (NaN for scenes with non-conservative loads).
    """

    q: Float[Array, "*batch n_dofs"]
    converged: Bool[Array, "*batch"]
    residual_norm: Float[Array, "*batch"]
    stable: Bool[Array, "*batch"]
    min_hessian_eigenvalue: Float[Array, "*batch"]
    steps: Int[Array, "*batch"]
    result: RESULTS
    energy: Float[Array, "*batch"]

    @property
    def successful(self) -> Bool[Array, "*batch"]:
        """``result == RESULTS.successful``: converged to a stable equilibrium."""
        return self.result == RESULTS.successful

    @property
    def reason(self) -> str | list[str]:
        """Why the solve stopped, in words (a list for a batch)."""
        return describe(self.result, "converged")
