"""Several equilibria of one scene: solves from random starts, deduplicated and ranked.

A soft robot under load can have more than one equilibrium for the same command (the paper notes
the non-uniqueness; a column past its buckling load has a straight saddle and bent minima).
:func:`find_equilibria` solves the same scene and controls from the straight configuration and
from random starts in one batch (:func:`pacjax.solve_batch`), merges the solutions that are the
same configuration, and reports each distinct equilibrium once with its energy, its stability
and how many starts reached it.

Two solutions are the same configuration when their backbones coincide: the positions and
orientations of frames along every segment agree to ``distance_tol``. Comparing shapes rather
than coordinates merges what a parametrisation tells apart but the body does not (PAC's
``(c, phi)`` and ``(-c, phi + pi)``; any ``phi`` of a straight segment).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
from jaxtyping import Array, Int

from .._jit import jit
from .._model.inputs import check_controls, check_int, check_scene, solver_dtype
from .._model.scene import Scene
from .._results import RESULTS
from .batch import solve_batch
from .options import SolverOptions
from .solution import Equilibrium

_POINTS_PER_SEGMENT = 4  # frames compared per segment (s = 1/4 .. 1)


class Equilibria(eqx.Module):
    """Distinct equilibria of one scene and command, lowest energy first.

    Attributes:
        equilibria: an :class:`Equilibrium` with a leading axis, one row per distinct
            equilibrium (all converged), sorted by energy (for scenes with follower loads,
            whose energy is NaN: stable ones first, then by how many starts found them).
        hits: how many starts converged to each equilibrium.
        n_starts: how many starts were solved.
        n_failed: how many of them did not converge (they are not in ``equilibria``).
    """

    equilibria: Equilibrium
    hits: Int[Array, " k"]
    n_starts: int = eqx.field(static=True)
    n_failed: int = eqx.field(static=True)

    def __len__(self) -> int:
        return int(self.hits.shape[0])

    def __getitem__(self, i: int) -> Equilibrium:
        """The ``i``-th equilibrium (0: lowest energy) as an unbatched :class:`Equilibrium`."""
        if not -len(self) <= i < len(self):
            raise IndexError(f"equilibrium {i} out of range ({len(self)} found)")
        return jtu.tree_map(lambda x: x[i], self.equilibria)

    @property
    def result(self) -> RESULTS:
        """``successful`` when at least one start converged, else ``no_equilibrium``."""
        return RESULTS.successful if len(self) else RESULTS.no_equilibrium

    @property
    def successful(self) -> bool:
        """Whether at least one equilibrium was found."""
        return len(self) > 0

    @property
    def q(self):
        return self.equilibria.q

    @property
    def energy(self):
        return self.equilibria.energy

    @property
    def stable(self):
        return self.equilibria.stable

    def summary(self) -> str:
        """A plain-text table: energy (J), stability, smallest scaled eigenvalue, hits."""
        lines = [
            f"{len(self)} distinct equilibria from {self.n_starts} starts "
            f"({self.n_failed} did not converge)",
            f"{'#':>3} {'energy (J)':>14} {'stable':>7} {'min eig':>10} {'hits':>5}",
        ]
        for i in range(len(self)):
            eq = self[i]
            lines.append(
                f"{i:>3} {float(eq.energy):>14.6e} {str(bool(eq.stable)):>7} "
                f"{float(eq.min_hessian_eigenvalue):>10.3e} {int(self.hits[i]):>5}"
            )
        return "\n".join(lines)


#: Default spreads of :func:`find_equilibria`'s starts (rad per segment): geometric from
#: near-straight, where a buckled column's minima are, to a full turn, where a hanging body's
#: curled branches are. With one spread of 1 rad, 170 starts missed the curled loop of a hanging
#: tendon-curled cable that 16 starts at pi found (``tests/test_multistart.py``).
SPREADS = (0.5, 2.0 * np.pi)


def random_starts(scene: Scene, n_starts: int, seed: int, spread, straight: bool):
    """Starting configurations ``(n_starts, n_dofs)``.

    Strain coordinates are uniform in ``[-spread, spread]`` (rad per segment; ``spread`` a
    number, or one per start), bending-plane angles (PAC/PCC ``phi``) uniform in ``[-pi, pi]``,
    elongations zero. With ``straight`` the first start is the straight configuration.
    Coordinates a scene pins (an inextensible segment's ``dL``, a lower-order segment's missing
    coefficients) are not drawn.
    """
    rng = np.random.default_rng(seed)
    names = scene.model.coordinate_names()
    strain = np.array([n not in ("phi", "dL") for n in names], float)
    angle = np.array([n == "phi" for n in names], float)
    spread = np.broadcast_to(np.asarray(spread, float), (n_starts,))[:, None, None]
    half_width = spread * strain + np.pi * angle
    unit = rng.uniform(-1.0, 1.0, size=(n_starts, scene.n_segments, len(names)))
    starts = np.array(scene.free_part(unit * half_width))
    if straight:
        starts[0] = 0.0
    return starts


@jit
def _shape_signatures(scene: Scene, qs):
    """Positions (m) and length-scaled rotations of frames along the robot, per row of ``qs``."""
    n = scene.n_segments
    segs = np.repeat(np.arange(n), _POINTS_PER_SEGMENT)
    s = np.tile(np.arange(1, _POINTS_PER_SEGMENT + 1) / _POINTS_PER_SEGMENT, n)
    length = scene.robot.total_length.astype(qs.dtype)

    def one(q):
        rot, pos = scene.frames(q, segs, jnp.asarray(s, q.dtype))
        return jnp.concatenate([pos.reshape(-1), length * rot.reshape(-1)])

    return jax.vmap(one)(qs)


def find_equilibria(
    scene: Scene,
    controls=None,
    *,
    n_starts: int = 16,
    seed: int = 0,
    spread: float | None = None,
    include_straight: bool = True,
    distance_tol: float | None = None,
    escapes: int = 0,
    **options,
) -> Equilibria:
    """Distinct equilibria of ``scene`` under ``controls``, found from several starts.

    Args:
        scene: the :class:`Scene`.
        controls: (n_tendons,) controls (default zeros), the same for every start.
        n_starts: number of starts, the straight one included.
        seed: seed of the random starts.
        spread: half-width (rad per segment) of the uniform distribution of the starting
            strain coordinates; bending-plane angles are drawn in ``[-pi, pi]``. Default: one
            per start, geometric from 0.5 rad to 2 pi (:data:`SPREADS`), so that both the
            shapes near straight and the curled branches of a hanging body are sampled.
            Every start is one row of one batch solve: the cost is that of
            :func:`pacjax.solve_batch` on ``n_starts`` rows.
        include_straight: make the first start the straight configuration (the one that lands
            on the straight saddle of a buckled column).
        distance_tol: two solutions are one equilibrium when frames along the robot are within
            this distance (m; rotations count scaled by the robot's length). Default: ``1e-6``
            of the robot's length in float64, ``1e-3`` in float32.
        escapes: saddle escapes per start (default 0: saddles are equilibria too, reported with
            ``stable=False``; the solver's own default leaves them).
        **options: further keyword arguments of :func:`pacjax.solve_batch` (``tol``,
            ``max_steps``, ``chunk_size``, ``fallback`` (default False here: a start that fails
            is just counted in ``n_failed``), ``initial_dt`` (default 1 here: each start follows
            the flow into its own basin), ...).

    Returns:
        :class:`Equilibria`, lowest energy first.
    """
    check_scene(scene)
    n_starts = check_int("n_starts", n_starts, 1)
    seed = check_int("seed", seed, 0)
    if spread is None:
        spread = np.geomspace(*SPREADS, n_starts)
    elif isinstance(spread, bool) or not np.isscalar(spread) or not np.isfinite(spread):
        raise ValueError(f"spread must be a finite number > 0, got {spread!r}")
    elif spread <= 0:
        raise ValueError(f"spread must be a finite number > 0, got {spread!r}")
    if distance_tol is not None and not (np.isscalar(distance_tol) and distance_tol > 0):
        raise ValueError(f"distance_tol must be a number > 0, got {distance_tol!r}")
    controls = np.asarray(check_controls(scene, controls, solver_dtype(scene)))
    options.setdefault("fallback", False)
    given = options.get("options")
    unset = given is None or (isinstance(given, SolverOptions) and given.initial_dt is None)
    if "initial_dt" not in options and unset:
        # Each start must stay in its own basin: the continuation from dt = 1 follows the flow
        # from it, where a solve's long first step from straight (POLAR_INITIAL_DT) can leap to
        # another basin (the hanging cable's loop of the tests was missed so).
        options["initial_dt"] = 1.0
    starts = random_starts(scene, n_starts, seed, spread, include_straight)
    batch = solve_batch(scene, np.tile(controls, (n_starts, 1)), starts, escapes=escapes, **options)

    converged = np.flatnonzero(np.asarray(batch.converged))
    dtype = batch.q.dtype
    if distance_tol is None:
        relative = 1e-6 if dtype == jnp.float64 else 1e-3
        distance_tol = relative * float(scene.robot.total_length)
    signatures = np.asarray(_shape_signatures(scene, batch.q[converged])) if converged.size else []
    residuals = np.asarray(batch.residual_norm)[converged]

    # Greedy clustering, best-converged solutions first: each becomes a representative unless
    # it coincides with one already kept.
    kept: list[int] = []  # positions in `converged`
    hits: list[int] = []
    for k in np.argsort(residuals, kind="stable"):
        for j, rep in enumerate(kept):
            if np.max(np.abs(signatures[k] - signatures[rep])) <= distance_tol:
                hits[j] += 1
                break
        else:
            kept.append(int(k))
            hits.append(1)

    rows = converged[kept] if kept else np.zeros(0, int)
    hits_arr = np.asarray(hits, int)
    energy = np.asarray(batch.energy)[rows]
    stable = np.asarray(batch.stable)[rows]
    order = np.lexsort((-hits_arr, ~stable, np.where(np.isnan(energy), np.inf, energy)))
    rows, hits_arr = rows[order], hits_arr[order]
    chosen = jtu.tree_map(lambda x: x[jnp.asarray(rows, int)], batch)
    return Equilibria(
        equilibria=chosen,
        hits=jnp.asarray(hits_arr),
        n_starts=n_starts,
        n_failed=int(n_starts - converged.size),
    )
