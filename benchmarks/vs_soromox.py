"""pacjax against SoRoMoX 0.5 (tud-phi/soromox, its GVS model) on the same two statics problems.

Usage: python benchmarks/vs_soromox.py [--problem a|b|all] [--rows 100,1000] [--repeats 3]
       [--grad-rows 100] [--models PAC,Poly1] [--quadrature 8] [--soromox-tol 1e-10]
       [--quick] [--json out.json]

SoRoMoX is an optional, benchmark-only dependency: ``pip install -e ".[bench]"``.

Problems (E = 5.05e5 Pa, Poisson 0.45, density 1500 kg/m^3, gravity (0, 0, -9.81) m/s^2, the
robot hanging from a clamped base at the origin along world -z):

- ``a``: the tentacle of ``shared/data/soromox_tentacle`` (the SoRoMoX paper's identification
  robot): 0.360 m, solid round section tapered linearly in two pieces (0.305 m: radius
  15.41 -> 6.42 mm; 0.055 m: 6.42 -> 4.80 mm), two tendons in tension mode anchored at the end
  of piece 1, in continuous channels at d(s) = 0.0114 - 0.0295 s m from the centreline, at world
  directions (0.5, +-0.866, 0) (60 degrees either side of +x). Rows: tension pairs uniform in
  [0, 8] N (seed 0).
- ``b``: a hanging cantilever, two segments of 0.15 m, constant radius 15 mm, under gravity and a
  world-fixed tip force (seed 1): magnitude uniform in [0, 2] N, direction uniform over the
  lower half of the sphere (no compressive load, so no buckling). The rod weighs 3.1 N, about
  the largest force: large 3D deflections, whose bending plane is the vertical plane of the
  force (which PAC's planar segments can follow).
  At 10 mm radius (1.4 N of weight) forces of 1.2 N and more swing it so far that SoRoMoX's
  undamped Newton failed on 2 % of the rows, and a ``vmap``-ped Newton costs every row its
  slowest row's steps (all 200); 15 mm keeps the comparison on rows both libraries solve.

The two set-ups (the same physics as far as both libraries allow):

- SoRoMoX: ``GVS`` with, per segment, a monomial strain basis on the bending strains
  ``kappa_y, kappa_z`` of order 1 (affine curvature in 3D) and the axial strain ``sigma_x`` of
  order 0 (uniform stretch); torsion ``kappa_x`` and the shears ``sigma_y, sigma_z`` are left
  out of the basis, i.e. rigid (no shear, no twist). ``LinkSpec.circular`` with the material
  and a ``LinearProfile`` radius, so ``EI(X)``, ``EA(X)`` and ``rho A(X)`` follow the taper;
  8 Gauss points per segment; the base pose is the quaternion of the same base rotation (local
  x, SoRoMoX's backbone axis, to world -z). Tendons: ``ThreadlikeRouting.linear`` (a continuous
  path at ``intercept + slope s`` in the material frame, ``s`` the backbone arc length in m)
  with ``ThreadlikeActuator.tendons`` (control = tension in N, force ``-dl/dq T``). The tip
  force enters as ``J^T F`` with ``J`` the linear rows of ``GVS.jacobian_tips`` (inertial
  frame; checked against automatic differentiation of the tip position). Statics: the residual
  ``K q + G(q) - B(q) u`` (``- J^T F``) solved by ``optimistix.Newton`` from the straight rest
  state ``q = 0``, ``max_steps=200``, ``jax.vmap`` over the rows: the recipe of SoRoMoX's
  system-identification script (``paper_results/secVa_system_identification``), there with
  rtol = atol = 1e-6, here ``--soromox-tol`` (default 1e-10; the residual ends near 1e-15).
- pacjax: ``pj.Segment`` from the same numbers: ``EI = E pi r0^4 / 4``, ``GJ = E / (2 (1 + nu))
  pi r0^4 / 2``, ``rho pi r0^2`` at the segment's base and ``radius_tip`` for the taper (``EI``
  and ``GJ`` scale with ``r^4``, the density with ``r^2``); the axial stiffness is not tapered in
  pacjax, so ``k_a = E pi mean(r^2) / L``, which is exactly GVS's ``int EA dX / L^2`` for a
  uniform stretch. Base rotation ``diag(1, -1, -1)``; each tendon's angle is that of the same
  world direction in pacjax's base frame. Tendons: ``routing="channel"`` (offset 0.0114 m at the
  base, 0.0114 - 0.0295 * 0.305 m at the anchor, linear in the route coordinate, which is the
  arc length here: the route lies in one segment) when ``pj.Tendon`` takes it, else 41 guide
  rings (straight chords, printed); tension mode. The tip force is a
  world-fixed ``pj.PointForce`` set per row (``solve_batch(params=..., update=...)``). Solved
  by ``pj.solve_batch`` (default options, tol 1e-10 on the scaled residual, ``fallback=False``
  as in ``pacjax bench``: the rate is the solver's own) from the straight state.
  ``pj.PolynomialCurvature(1)`` ("Poly1": ``kx, ky`` affine plus the stretch ``dL``, per
  segment) has exactly GVS's configuration space and energy; ``pj.PAC()`` is the paper's polar
  form.

What still differs (the tip differences measure it):

- kinematics integration: pacjax's frames are in closed form for PAC and 4th-order Magnus in 4
  sub-steps per segment for Poly1, positions by Gauss-Legendre; GVS takes a 4th-order Magnus
  step between consecutive Gauss points; both approximate the same curve (gravity and the
  tendon length use the same 8 nodes per segment in both). On (a) the tips then differ by
  ~0.03 mm; with 16 and 32 points per segment in both (``--quadrature``) by ~0.002 and
  ~0.0002 mm: discretisation, not physics;
- PAC (not Poly1): one bending plane per segment (``k0 || k1``) and its stiffness ``GJ / L`` on
  the plane angle ``phi``; the loads here bend the robot in one plane, so this shows only near
  straight rows, where ``phi`` must turn to a weak load (on (b), 0.08 mm at a 0.75 mN force);
- pacjax's contraction end stop (zero energy until 85 % contraction; inactive here);
- with rings instead of a channel, the tendon is a chain of chords, not the channel's curve
  (41 rings: tips up to 4.4 mm from SoRoMoX's on 16 rows of (a)).

``pj.presets.tentacle`` is the same robot but for its axial stiffness, ``E pi r0 r1 / L`` (the
end-load stiffness of a tapered rod: the least energy of any strain along it with the same total
elongation); SoRoMoX's uniform stretch is ``E pi mean(r^2) / L``, 27 % stiffer for piece 1, and
the tendons compress the body by up to ~2 cm: with the preset the tips lie up to 7.6 mm from
SoRoMoX's (16 rows of (a)), hence this script's own scene.

Measured per library, problem and batch size: compile time (first call minus the median warm
call), warm equilibria per second (median of ``--repeats`` warm calls, the libraries
alternated, which goes first swapped every repeat), the fraction converged (pacjax:
``Equilibrium.converged``; SoRoMoX: ``result == successful``), the largest residual (pacjax:
its scaled residual; SoRoMoX: ``max_i |F_i| / K_ii``, the same units of strain, and
``max |F|`` in N m), the solver steps per equilibrium (pacjax: ``Equilibrium.steps``; SoRoMoX:
``stats["num_steps"]``), the largest tip distance (mm) between the libraries on rows both
solved, and ``jax.value_and_grad`` of the sum of the tip coordinates over ``--grad-rows`` rows
w.r.t. Young's modulus (both implicit: pacjax through a ``vmap`` of ``pj.solve_equilibrium``,
since ``pj.solve_batch`` is not traceable (it pools rows in Python); SoRoMoX through
``optimistix``'s implicit adjoint, the model rebuilt by ``GVS.with_isotropic_material``).
Ratios are pacjax's rate over SoRoMoX's. The record goes to
``benchmarks/results/vs_soromox/<date>_<commit>.json``. Nothing is asserted.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.metadata
import inspect
import json
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import pacjax as pj

jax.config.update("jax_enable_x64", True)

try:
    import optimistix as optx
    from scipy.spatial.transform import Rotation
    from soromox.actuation import ThreadlikeActuator, ThreadlikeRouting
    from soromox.systems import (
        GVS,
        GVSSegment,
        IsotropicMaterialParams,
        JointSpec,
        LinearProfile,
        LinkSpec,
        StrainBasisSpec,
    )
except ImportError as err:  # the optional extra is missing
    sys.exit(f"SoRoMoX is needed for this benchmark: pip install -e '.[bench]' ({err})")

HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS_DIR = os.path.join(HERE, "results", "vs_soromox")

#: Material (the tentacle README's starting guess), SI units.
YOUNG = 5.05e5
POISSON = 0.45
DENSITY = 1500.0
GRAVITY = 9.81
#: Base rotation (base frame -> world) of pacjax's hanging robot: its axis +z to world -z.
PACJAX_HANGING = np.diag([1.0, -1.0, -1.0])
#: The same for SoRoMoX, whose backbone runs along local x: local x to world -z.
SOROMOX_HANGING = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])

#: Tentacle pieces: (length m, base radius m, tip radius m).
TENTACLE = ((0.305, 0.01541, 0.00642), (0.055, 0.00642, 0.00480))
#: Channel distance from the centreline, d(s) = intercept + slope s, s in m from the base.
CHANNEL_INTERCEPT = 0.0114
CHANNEL_SLOPE = -0.0295
#: World directions of the two tendons from the centreline at rest.
TENDON_DIRECTIONS = np.array([[0.5, np.sqrt(3) / 2, 0.0], [0.5, -np.sqrt(3) / 2, 0.0]])
MAX_TENSION = 8.0
RING_GUIDES = np.linspace(0.0, 1.0, 41)

#: Cantilever pieces as the tentacle's (here uniform), and the largest tip force (N).
CANTILEVER = ((0.15, 0.015, 0.015), (0.15, 0.015, 0.015))
MAX_TIP_FORCE = 2.0

MODELS = {"PAC": pj.PAC, "Poly1": lambda: pj.PolynomialCurvature(1)}


def timed(fn):
    """``(seconds, result)`` of ``fn()``, waiting for every array of the result."""
    start = time.perf_counter()
    out = fn()
    jax.block_until_ready(out)
    return time.perf_counter() - start, out


# ------------------------------------------------------------------------------ the problems
@dataclass(frozen=True)
class Problem:
    """One statics problem as both libraries see it.

    ``rows(n)``: the per-row inputs (tensions (n, 2) in N, or tip forces (n, 3) in N);
    ``tendons``: whether the rows are tendon tensions (else world tip forces);
    ``pieces``: (length, base radius, tip radius) per segment.
    """

    name: str
    title: str
    pieces: tuple
    tendons: bool
    rows: Callable[[int], np.ndarray]


def tension_rows(n: int) -> np.ndarray:
    return np.random.default_rng(0).uniform(0.0, MAX_TENSION, (n, 2))


def tip_force_rows(n: int) -> np.ndarray:
    rng = np.random.default_rng(1)
    direction = rng.normal(size=(n, 3))
    direction[:, 2] = -np.abs(direction[:, 2])  # lower half sphere: pulls down or sideways
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return direction * rng.uniform(0.0, MAX_TIP_FORCE, (n, 1))


PROBLEMS = {
    "a": Problem(
        "a", "tentacle, two channel tendons, tensions in [0, 8] N", TENTACLE, True, tension_rows
    ),
    "b": Problem(
        "b", "hanging cantilever, world tip force up to 2 N", CANTILEVER, False, tip_force_rows
    ),
}


def channel_available() -> bool:
    """Whether this pacjax's ``Tendon`` takes ``routing=`` (continuous channels)."""
    return "routing" in inspect.signature(pj.Tendon).parameters


# ------------------------------------------------------------------------------ pacjax side
def pacjax_scene(problem: Problem, model, young=YOUNG, quadrature: int = 8) -> pj.Scene:
    """The problem's pacjax scene; ``young`` may be traced (for the gradient)."""
    shear = young / (2.0 * (1.0 + POISSON))
    segments = []
    for length, r0, r1 in problem.pieces:
        inertia = np.pi * r0**4 / 4.0
        mean_area = np.pi * (r0**2 + r0 * r1 + r1**2) / 3.0  # mean of pi r(s)^2, r linear
        segments.append(
            pj.Segment(
                length=length,
                bending_stiffness=young * inertia,
                axial_stiffness=young * mean_area / length,
                torsion_stiffness=shear * 2.0 * inertia,
                linear_density=DENSITY * np.pi * r0**2,
                radius=r0,
                radius_tip=None if r1 == r0 else r1,
            )
        )
    robot = pj.Robot(segments, base_rotation=PACJAX_HANGING)
    loads = [pj.Gravity(g=GRAVITY)]
    tendons = []
    if problem.tendons:
        in_base = TENDON_DIRECTIONS @ PACJAX_HANGING  # rows: R^T w
        routing = {"routing": "channel"} if channel_available() else {"guides": RING_GUIDES}
        anchor = CHANNEL_INTERCEPT + CHANNEL_SLOPE * problem.pieces[0][0]
        tendons = [
            pj.Tendon(
                0,
                float(np.arctan2(d[1], d[0])),
                CHANNEL_INTERCEPT,
                s=1.0,
                offset_end=anchor,
                mode="tension",
                **routing,
            )
            for d in in_base
        ]
    else:
        loads.append(pj.PointForce(np.zeros(3), len(segments) - 1, 1.0))
    return pj.Scene(robot, model, tendons=tendons, loads=loads, quadrature_points=quadrature)


def _with_tip_force(scene: pj.Scene, force) -> pj.Scene:
    return eqx.tree_at(lambda s: s.loads[1].force, scene, force)


def pacjax_batch(problem: Problem, scene: pj.Scene, rows: np.ndarray):
    """``pj.solve_batch`` of every row; returns the :class:`pj.Equilibrium` batch."""
    if problem.tendons:
        return pj.solve_batch(scene, rows, fallback=False, progress=False)
    return pj.solve_batch(
        scene,
        np.zeros((len(rows), 0)),
        params=rows,
        update=_with_tip_force,
        fallback=False,
        progress=False,
    )


def pacjax_tips(scene: pj.Scene, q) -> np.ndarray:
    return np.asarray(jax.vmap(lambda x: pj.tip_pose(scene, x)[0])(q))


def pacjax_gradient(problem: Problem, model, quadrature: int):
    """``jit(value_and_grad)`` of ``(young, rows) -> sum of the tips' coordinates``."""

    def loss(young, rows):
        scene = pacjax_scene(problem, model, young, quadrature)

        def tip(row):
            if problem.tendons:
                eq = pj.solve_equilibrium(scene, row, fallback=False)
                return pj.tip_pose(scene, eq.q)[0]
            sc = _with_tip_force(scene, row)
            return pj.tip_pose(sc, pj.solve_equilibrium(sc, fallback=False).q)[0]

        return jnp.sum(jax.vmap(tip)(rows))

    return jax.jit(jax.value_and_grad(loss))


# ------------------------------------------------------------------------------ SoRoMoX side
def soromox_robot(problem: Problem, quadrature: int = 8) -> GVS:
    """The problem as a SoRoMoX ``GVS`` (affine bending, uniform stretch, no twist or shear)."""
    basis = StrainBasisSpec(
        type="monomial", strain_selector=[0, 1, 1, 1, 0, 0], basis_order=[0, 1, 1, 0, 0, 0]
    )
    segments = [
        GVSSegment(
            link=LinkSpec.circular(
                length=length,
                radius=r0 if r1 == r0 else LinearProfile(base=r0, tip=r1),
                density=DENSITY,
                young_modulus=YOUNG,
                poisson_ratio=POISSON,
                reference_strain=[0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
            ),
            joint=JointSpec(type="fixed"),
            basis=basis,
            num_gauss_points=quadrature,
        )
        for length, r0, r1 in problem.pieces
    ]
    pose = np.concatenate([Rotation.from_matrix(SOROMOX_HANGING).as_quat(), np.zeros(3)])
    kwargs = {}
    if problem.tendons:
        local = TENDON_DIRECTIONS @ SOROMOX_HANGING  # rows: R^T w, x (the axis) is 0
        routing = ThreadlikeRouting.linear(
            intercept=CHANNEL_INTERCEPT * local,
            slope=CHANNEL_SLOPE * local,
            start_segment_index=0,
            end_segment_index=(0, 0),
        )
        kwargs["actuators"] = ThreadlikeActuator.tendons(routing)
    return GVS.from_segments(
        segments,
        gravity=jnp.array([0.0, 0.0, -GRAVITY]),
        base_pose=jnp.asarray(pose),
        scale_rotational_basis_by_length=True,
        **kwargs,
    )


def _soromox_rows(problem: Problem, robot: GVS, rows, tol: float, max_steps: int):
    """Per row: tip, converged, Newton steps, max |F| (N m), max |F_i| / K_ii."""
    solver = optx.Newton(rtol=tol, atol=tol)

    def residual(q, args):
        row, rb = args
        if problem.tendons:
            load = rb.actuation_matrix(q) @ row
        else:
            load = rb.jacobian_tips(q)[-1, 3:].T @ row  # world tip force -> J^T F
        return rb.K @ q + rb.gravitational_force(q) - load

    q0 = jnp.zeros(robot.K.shape[0])
    k_diag = jnp.diag(robot.K)

    def one(row):
        sol = optx.root_find(residual, solver, q0, (row, robot), max_steps=max_steps, throw=False)
        f = jnp.abs(residual(sol.value, (row, robot)))
        return (
            robot.forward_kinematics_tips(sol.value)[-1, :3, 3],
            sol.result == optx.RESULTS.successful,
            sol.stats["num_steps"],
            jnp.max(f),
            jnp.max(f / k_diag),
        )

    return jax.vmap(one)(rows)


def soromox_solver(problem: Problem, tol: float, max_steps: int):
    return eqx.filter_jit(lambda robot, rows: _soromox_rows(problem, robot, rows, tol, max_steps))


def soromox_gradient(problem: Problem, tol: float, max_steps: int):
    """``value_and_grad`` of ``(young, robot, rows) -> sum of the tips' coordinates``."""

    def loss(young, robot, rows):
        rb = robot.with_isotropic_material(
            IsotropicMaterialParams(young_modulus=young, poisson_ratio=POISSON)
        )
        return jnp.sum(_soromox_rows(problem, rb, rows, tol, max_steps)[0])

    return eqx.filter_jit(jax.value_and_grad(loss))


# ------------------------------------------------------------------------------ one problem
def alternate(calls: dict, repeats: int, log, tag: str):
    """First call of every subject (compile and run), then ``repeats`` warm rounds that call
    each subject once, in turn, the order reversed every other round.

    Returns the first-call seconds, the first results and the warm seconds, by subject name."""
    first, results, warm = {}, {}, {name: [] for name in calls}
    for name, call in calls.items():
        first[name], results[name] = timed(call)
        log(f"  {tag} {name}: first call {first[name]:.1f} s")
    names = list(calls)
    for r in range(repeats):
        for name in names if r % 2 == 0 else names[::-1]:
            warm[name].append(timed(calls[name])[0])
        log(f"  {tag} warm round {r + 1}: " + ", ".join(f"{k} {warm[k][-1]:.3f} s" for k in names))
    return first, results, warm


def timing_entry(n: int, first: float, warm: list, soromox_warm: float) -> dict:
    w = float(np.median(warm))
    return {
        "compile_s": max(first - w, 0.0),
        "first_call_s": first,
        "warm_s": w,
        "warm_all_s": warm,
        "equilibria_per_s": n / w,
        "rate_vs_soromox": soromox_warm / w,
    }


def soromox_entry(tips, converged, steps, residual, scaled_residual) -> dict:
    return {
        "converged": float(np.mean(converged)),
        "max_residual_scaled": float(np.max(scaled_residual)),
        "max_residual_abs_Nm": float(np.max(residual)),
        "steps_mean": float(np.mean(steps)),
        "steps_max": int(np.max(steps)),
    }


def pacjax_entry(eq, scene: pj.Scene, soromox_tips, soromox_converged) -> dict:
    """Convergence, residual and steps of a pacjax batch, and its tips against SoRoMoX's on
    the rows both solved."""
    ok = np.asarray(eq.converged)
    both = ok & soromox_converged
    dist = 1e3 * np.linalg.norm(pacjax_tips(scene, eq.q) - soromox_tips, axis=1)[both]
    entry = {
        "converged": float(np.mean(ok)),
        "stable": float(np.mean(np.asarray(eq.stable))),
        "max_residual_scaled": float(np.max(np.asarray(eq.residual_norm))),
        "steps_mean": float(np.mean(np.asarray(eq.steps))),
        "steps_max": int(np.max(np.asarray(eq.steps))),
        "rows_both_converged": int(both.sum()),
        "tip_diff_max_mm": None,
        "tip_diff_median_mm": None,
        "tip_diff_argmax_row": None,
    }
    if dist.size:
        entry["tip_diff_max_mm"] = float(dist.max())
        entry["tip_diff_median_mm"] = float(np.median(dist))
        entry["tip_diff_argmax_row"] = int(np.flatnonzero(both)[dist.argmax()])
    return entry


def run_problem(problem: Problem, sizes, repeats, grad_rows, models, args, log, out, save):
    """Fill ``out`` with the problem's measurements, calling ``save()`` after each of them (a
    run stopped by a time limit keeps what it measured)."""
    quad = args.quadrature
    all_rows = problem.rows(max(sizes + [grad_rows]))
    robot = soromox_robot(problem, quad)
    sm_solve = soromox_solver(problem, args.soromox_tol, args.soromox_max_steps)
    scenes = {name: pacjax_scene(problem, MODELS[name](), quadrature=quad) for name in models}
    out.update(title=problem.title, sizes={})
    if problem.tendons:
        out["pacjax_tendon_routing"] = "channel" if channel_available() else "rings (41 guides)"
        log(f"  pacjax tendons: {out['pacjax_tendon_routing']}")

    for n in sizes:
        rows = all_rows[:n]
        rows_j = jnp.asarray(rows)
        calls = {
            f"pacjax {m}": (lambda sc=scenes[m], rows=rows: pacjax_batch(problem, sc, rows))
            for m in models
        }
        calls["SoRoMoX GVS"] = lambda rows_j=rows_j: sm_solve(robot, rows_j)
        first, results, warm = alternate(calls, repeats, log, f"[{problem.name} n={n}]")
        sm_rows = [np.asarray(x) for x in results["SoRoMoX GVS"]]
        sm_warm = float(np.median(warm["SoRoMoX GVS"]))
        entries = {}
        for name in calls:
            entry = timing_entry(n, first[name], warm[name], sm_warm)
            if name == "SoRoMoX GVS":
                entry.update(soromox_entry(*sm_rows))
            else:
                scene = scenes[name.split()[1]]
                entry.update(pacjax_entry(results[name], scene, *sm_rows[:2]))
            entries[name] = entry
        out["sizes"][str(n)] = entries
        save()

    if grad_rows:
        out["gradient"] = run_gradient(problem, robot, all_rows[:grad_rows], models, args, log)
        save()


def run_gradient(problem: Problem, robot: GVS, rows, models, args, log) -> dict:
    """Warm time of d(sum of tips)/dE through a batch, both libraries alternated."""
    young = jnp.asarray(YOUNG)
    rows_j = jnp.asarray(rows)
    calls = {}
    for m in models:
        grad = pacjax_gradient(problem, MODELS[m](), args.quadrature)
        calls[f"pacjax {m}"] = lambda g=grad: g(young, rows_j)
    sm_grad = soromox_gradient(problem, args.soromox_tol, args.soromox_max_steps)
    calls["SoRoMoX GVS"] = lambda: sm_grad(young, robot, rows_j)
    first, values, warm = alternate(
        calls, args.repeats, log, f"[{problem.name} grad n={len(rows)}]"
    )
    names = list(calls)
    sm_warm = float(np.median(warm["SoRoMoX GVS"]))
    sm_value = float(values["SoRoMoX GVS"][1])
    out = {"rows": len(rows), "loss": "sum over rows of tip x + y + z (m); d/dE in m/Pa"}
    for name in names:
        w = float(np.median(warm[name]))
        value, grad = (float(x) for x in values[name])
        out[name] = {
            "compile_s": max(first[name] - w, 0.0),
            "warm_s": w,
            "warm_all_s": warm[name],
            "batches_per_s": 1.0 / w,
            "rate_vs_soromox": sm_warm / w,
            "loss": value,
            "dloss_dE": grad,
            "rel_diff_vs_soromox": abs(grad - sm_value) / abs(sm_value),
        }
    return out


# ------------------------------------------------------------------------------ record, table
def machine() -> dict:
    try:
        lscpu = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
        model = next(
            (
                ln.split(":", 1)[1].strip()
                for ln in lscpu.splitlines()
                if ln.startswith("Model name")
            ),
            None,
        )
    except (OSError, subprocess.CalledProcessError):
        model = None
    return {
        "cpu": model or platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "jax": jax.__version__,
        "jaxlib": importlib.metadata.version("jaxlib"),
        "backend": jax.default_backend(),
        "accelerator": None if jax.default_backend() == "cpu" else jax.devices()[0].device_kind,
        "device_count": jax.device_count(),
        "x64": bool(jax.config.jax_enable_x64),
        "compilation_cache": jax.config.jax_compilation_cache_dir,
        "soromox": importlib.metadata.version("soromox"),
        "optimistix": importlib.metadata.version("optimistix"),
        "pacjax": pj.__version__,
    }


def git(*cmd) -> str:
    """Output of a git command run at the repository's root."""
    try:
        return subprocess.run(
            ["git", *cmd], cwd=os.path.dirname(HERE), capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def print_tables(record: dict) -> None:
    m = record["machine"]
    print(
        f"\n# pacjax vs SoRoMoX {m['soromox']} on "
        + (f"{m['accelerator']}, " if m.get("accelerator") else "")
        + f"{m['cpu']} ({m['cpu_count']} cores), "
        f"jax {m['jax']}, {record['date']}, commit {record['commit']}"
        + (" (+ uncommitted changes)" if record["dirty"] else "")
    )
    for key, prob in record["problems"].items():
        print(
            f"\n## ({key}) {prob['title']}"
            + (
                f"; pacjax tendons: {prob['pacjax_tendon_routing']}"
                if "pacjax_tendon_routing" in prob
                else ""
            )
        )
        print(
            "\n| library | rows | compile (s) | warm (s) | eq/s | vs SoRoMoX | conv. "
            "| max residual | steps mean / max | tip diff max / median (mm) |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|")
        for n, entries in prob["sizes"].items():
            for name, e in entries.items():
                tip = (
                    "-"
                    if "tip_diff_max_mm" not in e or e["tip_diff_max_mm"] is None
                    else f"{e['tip_diff_max_mm']:.4f} / {e['tip_diff_median_mm']:.4f}"
                )
                print(
                    f"| {name} | {n} | {e['compile_s']:.1f} | {e['warm_s']:.3f} | "
                    f"{e['equilibria_per_s']:.0f} | {e['rate_vs_soromox']:.2f} | "
                    f"{e['converged']:.1%} | {e['max_residual_scaled']:.1e} | "
                    f"{e['steps_mean']:.2f} / {e['steps_max']} | {tip} |"
                )
        if "gradient" in prob:
            g = prob["gradient"]
            print(f"\nGradient of the sum of tip coordinates over {g['rows']} rows w.r.t. E:")
            print(
                "\n| library | compile (s) | warm (s) | batches/s | vs SoRoMoX | dloss/dE (m/Pa) "
                "| rel. diff |"
            )
            print("|---|---|---|---|---|---|---|")
            for name, e in g.items():
                if not isinstance(e, dict):
                    continue
                print(
                    f"| {name} | {e['compile_s']:.1f} | {e['warm_s']:.3f} | "
                    f"{e['batches_per_s']:.2f} | {e['rate_vs_soromox']:.2f} | "
                    f"{e['dloss_dE']:.6e} | {e['rel_diff_vs_soromox']:.1e} |"
                )
    print("\nresidual: pacjax's scaled residual; SoRoMoX max_i |F_i| / K_ii (both in strain).")


def main():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--problem", choices=("a", "b", "all"), default="all")
    parser.add_argument(
        "--rows", default=None, help="comma-separated batch sizes (default: a 100,1000; b 1000)"
    )
    parser.add_argument("--repeats", type=int, default=3, help="warm calls per subject")
    parser.add_argument("--grad-rows", type=int, default=100, help="0: no gradient")
    parser.add_argument("--models", default="PAC,Poly1", help=f"of {','.join(MODELS)}")
    parser.add_argument("--quadrature", type=int, default=8, help="Gauss points per segment")
    parser.add_argument("--soromox-tol", type=float, default=1e-10)
    parser.add_argument("--soromox-max-steps", type=int, default=200)
    parser.add_argument("--quick", action="store_true", help="16 rows, 1 repeat, 8 grad rows")
    parser.add_argument("--json", default=None, help="record path (default: results/...)")
    args = parser.parse_args()
    models = [m for m in args.models.split(",") if m]
    unknown = set(models) - set(MODELS)
    if unknown:
        parser.error(f"unknown models {sorted(unknown)}; choose from {list(MODELS)}")
    if args.quick:
        args.repeats, args.grad_rows = 1, min(args.grad_rows, 8)
    keys = ("a", "b") if args.problem == "all" else (args.problem,)
    defaults = {"a": [100, 1000], "b": [1000]}

    # pacjax as measured: the commit plus whatever is uncommitted under pacjax/.
    changed = [
        ln.split(maxsplit=1)[-1] for ln in git("status", "--porcelain", "--", "pacjax").splitlines()
    ]
    record = {
        "date": datetime.date.today().isoformat(),
        "commit": git("rev-parse", "--short", "HEAD") or "unknown",
        "dirty": bool(changed),
        "changed_pacjax_files": changed,
        "command": " ".join([os.path.basename(sys.argv[0]), *sys.argv[1:]]),
        "machine": machine(),
        "settings": {
            "repeats": args.repeats,
            "grad_rows": args.grad_rows,
            "models": models,
            "quadrature_points": args.quadrature,
            "soromox_newton_rtol_atol": args.soromox_tol,
            "soromox_max_steps": args.soromox_max_steps,
            "pacjax_tol": 1e-10,
        },
        "problems": {},
    }

    def log(msg):
        print(msg, flush=True)

    log(
        f"pacjax {pj.__version__}, SoRoMoX {record['machine']['soromox']}, jax {jax.__version__}"
        f", {record['machine']['cpu']}; pacjax channel tendons: {channel_available()}"
    )
    path = args.json
    if path is None:
        suffix = "_quick" if args.quick else ""
        path = os.path.join(RESULTS_DIR, f"{record['date']}_{record['commit']}{suffix}.json")
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)

    def save():
        with open(path, "w") as f:
            json.dump(record, f, indent=2)

    for key in keys:
        if args.quick:
            sizes = [16]
        elif args.rows:
            sizes = [int(x) for x in args.rows.split(",")]
        else:
            sizes = defaults[key]
        log(f"problem ({key}): {PROBLEMS[key].title}, rows {sizes}")
        out = record["problems"][key] = {}
        run_problem(
            PROBLEMS[key], sizes, args.repeats, args.grad_rows, models, args, log, out, save
        )
        # The machine may be shared: how busy it was when this problem ended.
        out["load_average_1min_end"] = os.getloadavg()[0]
        save()
    print_tables(record)
    print(f"\nrecord: {os.path.relpath(path)}")


if __name__ == "__main__":
    main()
