"""How a solve ended: :class:`RESULTS`, the one result enumeration of every pacjax solve.

Each result object (:class:`pacjax.Equilibrium`, :class:`pacjax.Equilibria`,
:class:`pacjax.InverseResult`, :class:`pacjax.Tracking`, :class:`pacjax.Trajectory`,
:class:`pacjax.IdentificationReport`) has a ``result``, an item of :class:`RESULTS` (one per
row of a batch), and a ``successful`` property (``result == RESULTS.successful``). As in
optimistix, items compare with ``==`` (a boolean array), survive ``jit`` and ``vmap``, and
``RESULTS[item]`` is the message.
"""

import equinox as eqx
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np


class RESULTS(eqx.Enumeration):
    """How a solve ended."""

    __module__ = "pacjax"

    successful = ""
    max_steps_reached = "hit the maximum number of steps before the residual fell below tolerance"
    nonfinite = "the residual or energy became NaN or infinite"
    stalled = "the step size collapsed: no step reduced the energy (or residual)"
    target_not_reached = (
        "target not reached: the closest pose found is returned (out of reach, or blocked by "
        "the bounds and limits)"
    )
    no_equilibrium = "no converged, stable equilibrium was found"
    integration_failed = (
        "the integration stopped before the final time: the step size fell below its minimum "
        "or the implicit stage equations did not converge"
    )
    converged_saddle = (
        "converged to an unstable equilibrium (a saddle or a maximum: the residual is below "
        "tolerance but the stiffness is not positive definite, and no escape along its "
        "negative curvature left it); `converged` is True, `stable` False"
    )
    branch_mismatch = (
        "frames left the data's equilibrium branch: another stable equilibrium fits their "
        "markers better, or every trial step takes them over a fold onto another branch"
    )


_ITEM = jtu.tree_structure(RESULTS.successful)


def code_of(result: RESULTS) -> np.ndarray:
    """The integer code(s) of a (batched) result: its index in :class:`RESULTS`, for files
    and for loops that carry codes as integers."""
    (value,) = jtu.tree_leaves(result)
    return np.asarray(value)


def from_code(code) -> RESULTS:
    """The result whose code (see :func:`code_of`) is ``code``; traceable, any shape."""
    return jtu.tree_unflatten(_ITEM, [jnp.asarray(code, jnp.int32)])


def describe(result: RESULTS, success: str) -> str | list[str]:
    """The message of a result in words, ``success`` for a successful one: a string for one
    result, a list for a batch."""
    codes = code_of(result)
    words = [success if k == 0 else RESULTS[from_code(np.int32(k))] for k in codes.reshape(-1)]
    return words[0] if codes.ndim == 0 else words


#: Integer codes of the members that loops carry as integers (the PTC state).
SUCCESSFUL = int(code_of(RESULTS.successful))
MAX_STEPS_REACHED = int(code_of(RESULTS.max_steps_reached))
NONFINITE = int(code_of(RESULTS.nonfinite))
STALLED = int(code_of(RESULTS.stalled))
CONVERGED_SADDLE = int(code_of(RESULTS.converged_saddle))
