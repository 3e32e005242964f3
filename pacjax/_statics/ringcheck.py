"""The warning that a ring-routed tendon's rings are too sparse for the curvature a solve
reached: a tendon that runs in a continuous channel, modelled by rings, gets the chords' shorter
moment arm (:func:`pacjax._model.channels.ring_chord_sag`). The tolerance separates the
tentacle of ``shared/data/soromox_tentacle`` modelled with up to 41 rings along its channels
(markers millimetres to decimetres from the channel model) from the paper's ring-stacked robot
(``benchmarks/RESULTS.md``, "Tendon channels").
"""

import warnings

import jax
import jax.numpy as jnp
import numpy as np

from .._jit import jit
from .._model.channels import ring_chord_sag

#: The chords' sag, relative to the tendon's offset, above which a solve warns.
SAG_TOLERANCE = 0.02
#: Rows checked per call (padded): one compiled check per scene structure.
_ROWS = 256


class SparseRingsWarning(UserWarning):
    """A ring-routed tendon's chords fall well short of a channel through the same rings."""


@jit
def _worst_sag(scene, q):
    return jnp.max(jax.vmap(lambda x: ring_chord_sag(scene, x))(q), axis=0)


_warned: set = set()


def _unwarned(scene) -> dict:
    """Ring-routed tendons not warned about yet: index -> key (its index and routing)."""
    keys = {
        i: (i, t.segment, t.s, t.bowden, t.guides)
        for i, t in enumerate(scene.tendons)
        if t.routing == "rings"
    }
    return {i: k for i, k in keys.items() if k not in _warned}


def check_rows(scene, q) -> None:
    """:func:`warn_sparse_rings` at the configurations ``q`` (``(rows, n_dofs)``; rows that are
    not finite are skipped), computed here in chunks of :data:`_ROWS` (one compiled program
    per scene structure). Nothing happens inside a trace."""
    if isinstance(q, jax.core.Tracer) or not _unwarned(scene):
        return
    rows = np.asarray(q).reshape(-1, scene.n_dofs)
    rows = rows[np.all(np.isfinite(rows), axis=1)]
    worst = np.zeros(scene.n_tendons)
    for start in range(0, len(rows), _ROWS):
        chunk = rows[start : start + _ROWS]
        padded = np.zeros((_ROWS, scene.n_dofs), chunk.dtype)
        padded[: len(chunk)] = chunk
        worst = np.maximum(worst, np.asarray(_worst_sag(scene, jnp.asarray(padded))))
    warn_sparse_rings(scene, worst)


def warn_sparse_rings(scene, sag) -> None:
    """Warn, once per tendon (its index and routing), when the chords of a ring-routed tendon
    sag more than :data:`SAG_TOLERANCE` of its offset below a channel through its rings
    (``sag``: :func:`pacjax._model.channels.ring_chord_sag` at a solution, or its largest over
    several). Nothing happens inside a trace."""
    if isinstance(sag, jax.core.Tracer):
        return
    sag = np.asarray(sag)
    for i, key in _unwarned(scene).items():
        if sag[i] > SAG_TOLERANCE:
            _warned.add(key)
            n_rings = len(scene.tendons[i].guides)
            warnings.warn(
                f"Scene.tendons[{i}]: its chords sag up to {sag[i]:.0%} of its offset below a "
                f"channel through the same rings ({n_rings} rings per segment are sparse for "
                "this curvature): if the tendon runs in a continuous channel use "
                "routing='channel', else add rings (pacjax.SparseRingsWarning)",
                SparseRingsWarning,
                stacklevel=4,
            )
