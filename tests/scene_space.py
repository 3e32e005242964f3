"""The space of scenes a user can write, and the properties every solve on them must have.

Shared by the fast profile in CI's slow test step (``tests/test_campaign.py``) and the deep
campaign (``benchmarks/campaign.py``).

A scene is a STRUCTURE (segments, strain models, extensibility, load kinds and sites, tendon
anchors, routing, ring counts and modes, precision: what a compilation depends on) and VALUES
(lengths, stiffnesses, densities, load magnitudes, tendon angles, offsets and gains, gravity
and base directions, controls: traced leaves). Structures are drawn by :func:`draw_structure`
from a seeded generator and a campaign runs many value draws per structure (hypothesis
strategies from :func:`values`), so its cost is one compilation per structure and operation.

Properties (:func:`check`): no Python exception from a solve (validation errors belong to the
scene's construction); no NaN or infinity in any result (an energy is NaN only for a
non-conservative scene, as documented); a converged result has a residual below tolerance; a
successful one is converged and stable; a batch row equals the single solve of the same
controls; gradients through the equilibrium are finite.
"""

from __future__ import annotations

import dataclasses
import math
import os
import traceback

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import strategies as st

import pacjax as pj
from pacjax._model.inputs import static_load_sites

MODELS = ("PCC", "PAC", "Poly0", "Poly1", "Poly2", "Poly3", "PAC+PCC", "Poly*")
RING_COUNTS = (2, 3, 5, 11, 40)
SEGMENT_COUNTS = (1, 1, 2, 2, 3, 3, 4, 5, 8, 12, 24)
TOLS = {"float64": 1e-10, "float32": 1e-4}
#: Tips of a batch row and its single solve agree to this fraction of the robot's length.
SAME_TIP = {"float64": 1e-6, "float32": 1e-3}


@dataclasses.dataclass(frozen=True)
class Structure:
    """What a compilation depends on."""

    models: tuple[str, ...]  # per segment: "PCC", "PAC", "Poly0".."Poly3"
    extensible: tuple[bool, ...]
    masses: tuple[tuple[int, float], ...]  # (segment, s)
    forces: tuple[tuple[int, float, bool], ...]  # (segment, s, follower)
    moments: tuple[tuple[int, float], ...]
    tendons: tuple[tuple[int, float, str, int, str, bool], ...]  # anchor, s, routing, rings,
    #   mode, bowden
    gravity: bool
    dtype: str

    @property
    def n_segments(self) -> int:
        return len(self.models)

    def describe(self) -> str:
        return (
            f"{self.n_segments} seg {'/'.join(sorted(set(self.models)))}, "
            f"{len(self.masses)} masses, {len(self.forces)} forces, {len(self.moments)} moments, "
            f"{len(self.tendons)} tendons, gravity {self.gravity}, {self.dtype}"
        )


def draw_structure(rng: np.random.Generator, *, max_segments: int = 24) -> Structure:
    """A random structure from the scene space."""
    n = int(rng.choice([k for k in SEGMENT_COUNTS if k <= max_segments]))
    kind = str(rng.choice(MODELS))
    if kind == "PAC+PCC":
        models = tuple(str(rng.choice(["PAC", "PCC"])) for _ in range(n))
    elif kind == "Poly*":
        models = tuple(f"Poly{int(rng.integers(0, 4))}" for _ in range(n))
    else:
        models = (kind,) * n
    extensible = tuple(bool(rng.random() < 0.9) for _ in range(n))

    def site():
        return int(rng.integers(0, n)), float(np.round(rng.uniform(0.05, 1.0), 3))

    gravity = bool(rng.random() < 0.85)
    n_masses = int(rng.choice([0, 0, 1, 2, 3, 5, 6, 7, 9, 16, 20])) if gravity else 0
    masses = tuple(site() for _ in range(n_masses))
    forces = tuple((*site(), bool(rng.random() < 0.3)) for _ in range(int(rng.integers(0, 3))))
    moments = tuple(site() for _ in range(int(rng.choice([0, 0, 0, 1, 2]))))
    tendons = []
    for _ in range(int(rng.choice([0, 1, 2, 2, 3, 4]))):
        anchor = int(rng.integers(0, n))
        s = float(rng.choice([1.0, 1.0, np.round(rng.uniform(0.2, 1.0), 3)]))
        routing = "channel" if rng.random() < 0.3 else "rings"
        rings = int(rng.choice(RING_COUNTS))
        mode = "tension" if rng.random() < 0.5 else "length"
        bowden = bool(anchor > 0 and rng.random() < 0.3)
        tendons.append((anchor, s, routing, rings, mode, bowden))
    dtype = "float32" if rng.random() < 0.25 else "float64"
    return Structure(models, extensible, masses, forces, moments, tuple(tendons), gravity, dtype)


def _log_uniform(low: float, high: float):
    return st.floats(math.log10(low), math.log10(high)).map(lambda x: 10.0**x)


def _unit_vector():
    return (
        st.tuples(*[st.floats(-1.0, 1.0)] * 3)
        .filter(lambda v: np.linalg.norm(v) > 0.1)
        .map(lambda v: tuple(np.asarray(v) / np.linalg.norm(v)))
    )


def values(structure: Structure):
    """A hypothesis strategy of the VALUES of a scene of ``structure``."""
    n = structure.n_segments
    segment = st.fixed_dictionaries(
        {
            "length": st.floats(0.03, 0.3),
            "bending_stiffness": _log_uniform(1e-4, 1e-1),  # N m^2
            "axial_stiffness": _log_uniform(1e2, 1e5),  # N/m
            "linear_density": st.floats(0.0, 0.5),  # kg/m
        }
    )
    tendon = st.fixed_dictionaries(
        {
            "angle": st.floats(-math.pi, math.pi),
            "offset": st.floats(0.002, 0.02),  # m
            "gain": _log_uniform(1e2, 1e5),  # N/m
            "pull": st.floats(0.0, 0.02),  # m, length mode
            "tension": st.floats(0.0, 5.0),  # N, tension mode
        }
    )
    k = len(structure.tendons)
    return st.fixed_dictionaries(
        {
            "segments": st.lists(segment, min_size=n, max_size=n),
            "tendons": st.lists(tendon, min_size=k, max_size=k),
            "masses": st.lists(
                st.floats(0.0, 0.2), min_size=len(structure.masses), max_size=len(structure.masses)
            ),
            "forces": st.lists(
                st.tuples(*[st.floats(-2.0, 2.0)] * 3),
                min_size=len(structure.forces),
                max_size=len(structure.forces),
            ),
            "moments": st.lists(
                st.tuples(*[st.floats(-0.05, 0.05)] * 3),
                min_size=len(structure.moments),
                max_size=len(structure.moments),
            ),
            "g": st.floats(0.0, 9.81),
            "gravity_direction": _unit_vector(),
            "base_axis": _unit_vector(),
            "base_angle": st.floats(-math.pi, math.pi),
        }
    )


def _model(name: str):
    if name == "PCC":
        return pj.PCC()
    if name == "PAC":
        return pj.PAC()
    return pj.PolynomialCurvature(int(name[-1]))


def _rotation(axis, angle) -> np.ndarray:
    a = np.asarray(axis, float)
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def build(structure: Structure, v: dict) -> tuple[pj.Scene, np.ndarray]:
    """The scene and controls of ``structure`` with values ``v``."""
    segments = [
        pj.Segment(**seg, extensible=ext)
        for seg, ext in zip(v["segments"], structure.extensible, strict=True)
    ]
    robot = pj.Robot(segments, base_rotation=_rotation(v["base_axis"], v["base_angle"]))
    loads = []
    if structure.gravity:
        loads.append(pj.Gravity(v["g"], v["gravity_direction"]))
    loads += [
        pj.PointMass(m, seg, s) for m, (seg, s) in zip(v["masses"], structure.masses, strict=True)
    ]
    loads += [
        pj.PointForce(np.asarray(f), seg, s, follower=follower)
        for f, (seg, s, follower) in zip(v["forces"], structure.forces, strict=True)
    ]
    loads += [
        pj.PointMoment(np.asarray(m), seg, s)
        for m, (seg, s) in zip(v["moments"], structure.moments, strict=True)
    ]
    tendons, controls = [], []
    for t, (anchor, s, routing, rings, mode, bowden) in zip(
        v["tendons"], structure.tendons, strict=True
    ):
        guides = None if routing == "channel" else tuple(np.linspace(0.0, 1.0, rings))
        tendons.append(
            pj.Tendon(
                anchor,
                t["angle"],
                t["offset"],
                s=s,
                bowden=bowden,
                mode=mode,
                gain=t["gain"] if mode == "length" else None,
                routing=routing,
                **({} if guides is None else {"guides": guides}),
            )
        )
        controls.append(t["pull"] if mode == "length" else t["tension"])
    models = [_model(m) for m in structure.models]
    scene = pj.Scene(
        robot,
        models if len(set(structure.models)) > 1 else models[0],
        tendons=tendons,
        loads=loads,
    )
    if structure.dtype == "float32":
        scene = pj.astype(scene, jnp.float32)
    return scene, np.asarray(controls, float)


# ------------------------------------------------------------------------------ properties
class PropertyFailure(AssertionError):
    """A solve broke one of the campaign's properties."""


_PACJAX = os.path.dirname(pj.__file__)


def is_validation_error(err: BaseException) -> bool:
    """A documented validation error: a ``ValueError`` or ``TypeError`` that pacjax's own code
    raised (its innermost frame is in the package), as a check of the inputs does before any
    compilation; one raised inside JAX or NumPy (a shape mismatch in a trace) is a crash."""
    if not isinstance(err, (ValueError, TypeError)) or err.__traceback__ is None:
        return False
    innermost = traceback.extract_tb(err.__traceback__)[-1].filename
    return os.path.abspath(innermost).startswith(_PACJAX + os.sep)


def _require(ok: bool, what: str) -> None:
    if not ok:
        raise PropertyFailure(what)


def _check_result(eq, scene: pj.Scene, tol: float, where: str) -> None:
    q = np.asarray(eq.q)
    _require(np.all(np.isfinite(q)), f"{where}: non-finite q ({eq.reason})")
    res = float(eq.residual_norm)
    _require(math.isfinite(res), f"{where}: non-finite residual ({eq.reason})")
    energy = float(eq.energy)
    _require(
        math.isfinite(energy) or not scene.is_conservative,
        f"{where}: non-finite energy of a conservative scene",
    )
    _require(math.isfinite(float(eq.min_hessian_eigenvalue)), f"{where}: non-finite eigenvalue")
    if bool(eq.converged):
        _require(res <= tol * (1.0 + 1e-6), f"{where}: converged with residual {res:.3g}")
    _require(
        bool(eq.successful) == (bool(eq.converged) and bool(eq.stable)),
        f"{where}: successful is not converged and stable ({eq.reason})",
    )
    if not bool(eq.successful):
        _require(eq.reason != "converged", f"{where}: failed without a reason")


def _tip(scene, q) -> np.ndarray:
    return np.asarray(pj.tip_pose(scene, q)[0], float)


def require_same_tip(
    scene, controls, q_single, q_batch, dtype: str, both_stable: bool = False
) -> str:
    """A batch row's tip equals its single solve's to ``SAME_TIP`` of the robot's length, or,
    where the two stopped at different points of the tolerance's ball around the equilibrium,
    after one Newton step on each one's residual. Returns ``"same"``, or ``"not isolated"``
    where the residual's Jacobian is singular to working precision at either point (a family
    of equilibria, such as a body free to turn about a symmetry: there any point of the family
    is an answer, and a Newton step is rounding amplified).

    Both solves stop once the residual is below the tolerance, wherever in that ball their
    paths enter it (their step counts differ where rounding picks another step size); on a
    soft body the ball's radius in position, the tolerance over the stiffness, can exceed
    ``SAME_TIP``. A Newton step from each point lands on the equilibrium to the square of that
    distance, so the polished tips must agree however soft the body.

    ``both_stable``: both solves succeeded (each a stable equilibrium by its own check). Where
    each point is then an isolated equilibrium of the scene (its Newton step moves its tip less
    than ``SAME_TIP``) and the two are apart, the scene has two stable equilibria and the two
    solves took one each: returns ``"another equilibrium"``. Which one a solve reaches from the
    same start is decided by rounding where the paths pass near the boundary between their
    basins, and a batch's width changes the rounding of its vectorised arithmetic."""
    length = float(scene.robot.total_length)
    allowed = SAME_TIP[dtype] * length
    gap = np.linalg.norm(_tip(scene, q_batch) - _tip(scene, q_single))
    if gap <= allowed:
        return "same"
    (single, cond_single), (batch, cond_batch) = (
        _newton_step(scene, controls, q) for q in (q_single, q_batch)
    )
    polished_gap = np.linalg.norm(_tip(scene, batch) - _tip(scene, single))
    if polished_gap <= allowed:
        return "same"
    # A Newton step known to no better than a thousandth: the equilibrium is not isolated.
    if max(float(cond_single), float(cond_batch)) * float(jnp.finfo(q_single.dtype).eps) > 1e-3:
        return "not isolated"
    moved = max(
        np.linalg.norm(_tip(scene, polished) - _tip(scene, q))
        for polished, q in ((single, q_single), (batch, q_batch))
    )
    if both_stable and moved <= allowed:
        return "another equilibrium"
    raise PropertyFailure(
        f"batch row 0 tip {gap:.3g} m from the single solve's ({polished_gap:.3g} m after a "
        "Newton step on each)"
    )


def ran_out_of_steps_on_the_way(scene, controls, single, row, dtype: str) -> str:
    """A batch row and its single solve that differ in outcome. Allowed only where the one that
    did not succeed ran out of steps on its way to the other's equilibrium: a slow convergence
    whose last steps the rounding decides, and the batch's width changes the rounding of its
    vectorised arithmetic. Its last point then lies where a Newton step takes it to the other's
    tip (:func:`require_same_tip`); returns ``"step limit"`` (or ``"not isolated"``)."""
    done, short = (single, row) if bool(single.successful) else (row, single)
    _require(
        bool(short.result == pj.RESULTS.max_steps_reached),
        f"batch row 0 {row.reason!r} but single {single.reason!r}",
    )
    same = require_same_tip(scene, controls, done.q, short.q, dtype)
    return "step limit" if same == "same" else same


def _newton_step(scene, controls, q):
    """``q - (dF/dq)^-1 F(q)`` for the scene's residual ``F``, and the condition number of
    ``dF/dq``; the load sites made constants first, as the solves make them, so that the step
    polishes the same discretisation (a traced site is no knot of the kinematics, which moves
    the quadrature of the weight: a residual of 1e-5 N on a body curled by 9 rad)."""
    return _newton_step_jit(static_load_sites(scene), controls, q)


@eqx.filter_jit  # compiled per draw (its sites are constants): only where two tips differ
def _newton_step_jit(scene, controls, q):
    controls = jnp.asarray(controls, q.dtype)
    force = scene.residual(q, controls)
    jac = jax.jacfwd(scene.residual)(q, controls)
    return q - jnp.linalg.solve(jac, force), jnp.linalg.cond(jac)


#: Step limit of the campaign's 10 ms simulations (``check``'s ``"simulate"``). A sane draw takes
#: 100-300 steps; a nearly massless body (1e-10 kg/m) runs to the limit, and the campaign's
#: programs, compiled at LLVM's level 0, run some 16 times slower than a user's: 5,000 steps held
#: one draw for over 20 minutes where 1,000 prove the bound as well.
SIMULATE_MAX_STEPS = 1_000


def check(
    scene: pj.Scene,
    controls: np.ndarray,
    dtype: str,
    operations: tuple[str, ...] = (),
    on_operation=lambda name: None,
) -> dict:
    """Solve ``scene`` singly and as a batch, and run the further ``operations`` (any of
    ``"gradient"``: the tip differentiated through the equilibrium; ``"find_equilibria"``: four
    starts; ``"simulate"``: 10 ms of motion, at most ``SIMULATE_MAX_STEPS`` steps); raise
    :class:`PropertyFailure` on a broken property. Returns what happened (result codes) for
    the campaign's tally. ``on_operation`` is told the name of each operation as it starts (a
    campaign that finds a draw hanging says in what)."""
    tol = TOLS[dtype]
    on_operation("single")
    single = pj.solve_equilibrium(scene, controls, fallback=False)
    _check_result(single, scene, tol, "solve_equilibrium")
    rows = np.stack([controls, 0.5 * controls])
    on_operation("batch")
    batch = pj.solve_batch(scene, rows, fallback=False, progress=False)
    first = jax.tree.map(lambda x: x[0], batch)
    for i in range(2):
        _check_result(jax.tree.map(lambda x, i=i: x[i], batch), scene, tol, f"solve_batch[{i}]")
    same = "same"
    if bool(first.successful) != bool(single.successful):
        same = ran_out_of_steps_on_the_way(scene, controls, single, first, dtype)
    elif bool(single.successful):
        same = require_same_tip(scene, controls, single.q, first.q, dtype, both_stable=True)
    out = {"single": pj.RESULTS[single.result] or "successful"}
    if same != "same":
        out["batch_vs_single"] = same
    if "gradient" in operations and scene.n_tendons and bool(single.successful):
        on_operation("gradient")
        grad = _tip_gradient(scene, jnp.asarray(controls, single.q.dtype))
        _require(np.all(np.isfinite(grad)), "non-finite gradient of the tip by the controls")
    if "find_equilibria" in operations:
        on_operation("find_equilibria")
        found = pj.find_equilibria(scene, controls, n_starts=4, fallback=False)
        for i in range(len(found)):
            _check_result(found[i], scene, tol, f"find_equilibria[{i}]")
        out["equilibria"] = len(found)
    if "simulate" in operations and all(
        float(seg.linear_density) > 0 for seg in scene.robot.segments
    ):
        on_operation("simulate")
        out["simulate"] = _simulate(scene, controls)
    return out


def _simulate(scene, controls) -> str:
    """10 ms of motion: its result code, or the validation error of a scene that cannot move
    (a segment too light for its mass matrix to be factorised)."""
    try:
        # A few thousand steps bound a draw's time; beyond them the result code says so.
        motion = pj.simulate(
            scene,
            (0.0, 0.01),
            controls,
            saveat=np.linspace(0.0, 0.01, 3),
            max_steps=SIMULATE_MAX_STEPS,
        )
    except (ValueError, TypeError) as err:
        if not is_validation_error(err):
            raise
        return f"rejected: {err}"
    if bool(motion.successful):
        _require(np.all(np.isfinite(np.asarray(motion.q))), "simulate: non-finite q, successful")
    return pj.RESULTS[motion.result] or "successful"


def _tip_gradient(scene, controls):
    return np.asarray(_tip_gradient_jit(scene, controls))


@eqx.filter_jit  # one compilation per structure: the scene's values are traced
def _tip_gradient_jit(scene, controls):
    def tip_x(u):
        eq = pj.solve_equilibrium(scene, u, fallback=False)
        return pj.tip_pose(scene, eq.q)[0][0]

    return jax.grad(tip_x)(controls)
