"""The result of an equilibrium solve."""

import equinox as eqx
import numpy as np
from jaxtyping import Array, Bool, Float, Int

# Result codes (an int array so that they survive jit and vmap).
SUCCESS = 0
MAX_STEPS = 1
NONFINITE = 2
STALLED = 3
REASONS = {
    SUCCESS: "converged",
    MAX_STEPS: "hit the maximum number of steps before the residual fell below tolerance",
    NONFINITE: "the residual or energy became NaN or infinite",
    STALLED: "the step size collapsed: no step reduced the energy (or residual)",
}


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
        steps: continuation steps plus Newton polish steps.
        result: a code: 0 converged, 1 max steps, 2 non-finite, 3 stalled (see :attr:`reason`).
        energy: potential energy (J) at ``q`` (NaN for scenes with non-conservative loads).
    """

    q: Float[Array, "*batch n_dofs"]
    converged: Bool[Array, "*batch"]
    residual_norm: Float[Array, "*batch"]
    stable: Bool[Array, "*batch"]
    min_hessian_eigenvalue: Float[Array, "*batch"]
    steps: Int[Array, "*batch"]
    result: Int[Array, "*batch"]
    energy: Float[Array, "*batch"]

    @property
    def reason(self) -> str | list[str]:
        """Why the solve stopped, in words (a list for a batch)."""
        return describe_codes(self.result, REASONS)


def describe_codes(codes, words: dict) -> str | list[str]:
    """Result code(s) in words: a string for one code, a list for a batch."""
    codes = np.asarray(codes)
    if codes.ndim == 0:
        return words[int(codes)]
    return [words[int(c)] for c in codes.reshape(-1)]
