"""Identification of stiffness, density, tendon and mocap parameters from static frames.

The model's marker predictions for every frame come from its equilibrium under that frame's
controls and loads. The fit minimises ``sum_frames sum_markers rho(|x_pred - x_meas| / noise)``
(``rho`` quadratic, or Huber with ``loss="huber"``), plus orientation terms when the data have
them, over internal coordinates ``theta``: the log of every positive parameter (a multiplier on
its starting value: positivity by reparametrisation, and well-scaled steps for values spanning
decades), and plain offsets for the rest (stiffening rate, mocap transform, marker stand-offs).

Each evaluation solves the batch of equilibria with :func:`pacjax.solve_batch` (chunked,
vmapped, warm-started from the previous iteration's equilibria) and then differentiates the
residuals with the implicit function theorem: at an equilibrium ``F(q*, theta) = 0``, so
``dq*/dtheta = -(dF/dq)^-1 dF/dtheta``: one small linear solve per frame, vmapped and compiled
once; nothing differentiates through solver iterations. (Differentiating a vmapped
``solve_equilibrium`` with ``jax.jacfwd`` gives the same numbers, but compiled ~2x longer than
the solve plus this Jacobian, and cannot warm-start between iterations.) The Jacobian is exact,
so the default optimiser is Levenberg-Marquardt (damped Gauss-Newton, Marquardt's diagonal
scaling), run as a Python loop because every trial point needs fresh equilibria from the batch
solver (a traced optimistix loop could not warm-start them or fall back per row); any optax
optimiser can be passed instead and is driven with the gradient ``J^T r``. The Jacobian at the
optimum gives the Laplace / Gauss-Newton covariance ``s^2 (J^T J)^-1``.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from .. import _deprecated
from .._model.frameloads import with_frame_loads
from .._model.inputs import check_int
from .._model.scene import Scene
from .._statics.options import SolverOptions, resolve_options
from .checks import check_data, check_settings
from .dataset import MocapDataset
from .descent import Descent, DescentSettings, descend, run_summary, starting_points
from .estimates import covariance, parameter_table
from .evaluation import Evaluator, FrameData
from .problem import (
    L2_DELTA,
    Prior,
    Problem,
    check_params,
    kabsch,
    make_blocks,
    theta_bounds,
)
from .report import FitErrors, IdentificationReport


def identify(
    scene: Scene,
    dataset: MocapDataset,
    params: Sequence[str] = ("bending_stiffness",),
    *,
    per_segment: Sequence[str] = (),
    bounds: dict | None = None,
    priors: dict | None = None,
    validation: MocapDataset | None = None,
    holdout: float | Sequence[int] = 0.0,
    seed: int = 0,
    mocap_transform=None,
    noise: float = 1e-3,
    orientation_noise: float = np.radians(1.0),
    loss: str = "l2",
    huber_delta: float = 3.0,
    optimizer="levenberg-marquardt",
    max_iterations: int = 50,
    tol: float = 1e-10,
    branch_starts: int = 8,
    n_starts: int = 1,
    stages: Sequence[Sequence[str]] | None = None,
    frame_update=None,
    chunk_size: int = 16,
    progress: bool | None = None,
    options: SolverOptions | None = None,
    solver_options: dict | None = None,
) -> tuple[Scene, IdentificationReport]:
    """Fit scene parameters to static motion-capture frames.

    Args:
        scene: the model with starting values (its structure, e.g. PCC or PAC, is kept).
        dataset: the frames (:class:`MocapDataset`); marker positions in the mocap frame.
        params: parameters to fit, any of ``bending_stiffness``, ``axial_stiffness``,
            ``torsion_stiffness``, ``linear_density``, ``stiffening`` (rate of an exponential
            stiffening with contraction, added at 0 where a segment has none), ``tendon_gain``
            (``kappa_P`` of the length-mode tendons), ``tendon_offset``, ``mocap_transform``
            (rotation and translation from the world frame to the mocap frame, any axis up),
            ``marker_offsets`` (each marker's stand-off from the backbone, local frame),
            ``young_modulus`` (Pa: EI, GJ and the axial stiffness in proportion, the section
            of :attr:`Segment.radius`/``inner_radius`` kept), ``density`` (kg/m^3),
            ``rest_curvature`` (every segment's, in its model's coordinates; 0 where a
            segment has none).
            Segment and tendon parameters are one shared factor on the starting values, or one
            value per segment / tendon when named in ``per_segment``.
        bounds: name -> ``(lower, upper)`` in the parameter's units (None for a side keeps
            its default), overriding :data:`pacjax._identify.problem.DEFAULT_BOUNDS`: x1e-3 to
            x1e3 the starting value for stiffnesses, densities per length and gains; E in
            [1e2, 1e12] Pa; rho in [1, 3e4] kg/m^3; rest curvature within +-4 pi; tendon
            offsets x0.1 to x10; marker offsets +-0.2 m from the start. No iterate leaves
            them; the report says which values end at one.
        priors: name -> ``(mean, std)`` in the parameter's units (a number, or one per
            fitted value): Gaussian priors, residual rows ``(value - mean) / std`` beside the
            data's (the report's std then include them).
        validation: held-out frames (or ``holdout``: a random fraction of ``dataset``, or
            the 0-based indices of the frames to hold out; default: the frames the dataset's
            own ``holdout`` marks, the CSV's ``holdout`` column).
        mocap_transform: starting ``(rotation, translation)``. Default: when fitted, the rigid
            alignment (Kabsch) of the starting model's markers to the data; otherwise the
            identity (the data are in the scene's world frame).
        noise: marker noise scale (m): residuals are in units of it.
        orientation_noise: orientation noise scale (rad) when the data carry orientations.
        loss: ``"l2"`` or ``"huber"`` (robust; quadratic up to ``huber_delta`` noise units of
            marker distance, linear beyond).
        optimizer: ``"levenberg-marquardt"`` or an ``optax.GradientTransformation``.
        max_iterations: iteration limit.
        tol: stop when the relative decrease of the loss falls below ``tol`` (or, for
            Levenberg-Marquardt, the step in the internal coordinates below ``sqrt(tol)``).
        branch_starts: scattered starts from which every frame is solved again at the fit's
            start and whenever it stops: a frame whose markers another stable equilibrium fits
            clearly better (RMSE below 80 % of its own and 3 ``noise`` lower) is moved to it
            and the fit resumes (at most
            :data:`pacjax._identify.descent.MAX_ROUNDS` times). 0 turns the checks off.
            Steps on which a frame jumps to another branch (its markers move further than the
            step's linearisation predicts plus 2 % of the robot's length) are rejected either
            way. See :class:`pacjax.Branches`.
        n_starts: fits from this many starting points, the best kept (lowest loss among the
            successful): the given values, then every positive parameter's factor drawn
            log-uniformly within x1/4..x4 of them (inside the bounds), the others as given.
        stages: parameter groups fitted one after the other, each stage starting from the
            last stage's values (e.g. ``[["bending_stiffness"], ["bending_stiffness",
            "linear_density"]]``); replaces ``params``. ``per_segment``, ``bounds`` and
            ``priors`` apply in the stages that fit the parameters they name. The report is
            the last stage's, with every stage's summary in ``report.stages``.
        frame_update: ``(scene, values) -> scene``, the hook that puts one frame's
            ``dataset.frame_values`` (traced arrays) into the scene: any per-frame change the
            dataset's loads, base and gravity directions do not cover (see
            :mod:`pacjax._model.frameloads`). It runs under ``vmap``: jax.numpy only.
        chunk_size: frames per compiled batch (every dataset is padded to whole chunks, so
            train and held-out frames share one compilation).
        progress: show a tqdm progress bar (default: when stderr is a terminal).
        options: :class:`pacjax.SolverOptions` of the frames' equilibria (default
            ``SolverOptions()``); a frame that fails is not retried with the diffrax flow.
        solver_options: deprecated: keyword arguments for :func:`pacjax.solve_batch` (use
            ``options``).

    Returns:
        ``(fitted_scene, report)``: the scene with the fitted values (and fitted marker
        offsets), and an :class:`IdentificationReport`.
    """
    t_start = time.perf_counter()
    dataset, validation = check_data(scene, dataset, validation, holdout, seed)
    check_settings(loss, noise, orientation_noise, huber_delta, max_iterations, optimizer)
    n_starts = check_int("n_starts", n_starts, 1)
    branch_starts = check_int("branch_starts", branch_starts, 0)
    if stages is not None:
        settings = dict(
            per_segment=per_segment,
            bounds=bounds,
            priors=priors,
            validation=validation,
            mocap_transform=mocap_transform,
            noise=noise,
            orientation_noise=orientation_noise,
            loss=loss,
            huber_delta=huber_delta,
            optimizer=optimizer,
            max_iterations=max_iterations,
            tol=tol,
            branch_starts=branch_starts,
            n_starts=n_starts,
            seed=seed,
            frame_update=frame_update,
            chunk_size=chunk_size,
            progress=progress,
            options=options,
            solver_options=solver_options,
        )
        return _staged(scene, dataset, stages, settings, t_start)
    scales = (noise, orientation_noise, huber_delta if loss == "huber" else None)
    fit = _build_problem(
        scene,
        dataset,
        validation,
        params,
        per_segment,
        mocap_transform,
        scales,
        bounds,
        frame_update,
    )
    chunk, batch_options = _batch_settings(chunk_size, options)
    if solver_options is not None:
        _deprecated.warn("identify(solver_options=...)", "identify(options=SolverOptions(...))")
        batch_options.update(solver_options)
    train = fit.evaluator(dataset, chunk, batch_options)
    if priors:
        train.prior = Prior(fit.problem, dict(priors))
    align = "mocap_transform" in params and mocap_transform is None
    fit, current, first_eval_s = _start(fit, train, np.zeros(fit.problem.n_theta), align)
    settings = DescentSettings(optimizer, max_iterations, tol, progress, branch_starts, seed)
    runs = []
    for k, theta in enumerate(starting_points(fit, n_starts, seed)):
        start = current if k == 0 else train(theta)
        if k and not start.valid[: fit.dataset.n_frames].any():
            continue  # no frame has an equilibrium at this start: nothing to descend from
        runs.append(descend(fit, train, theta, start, settings))
    best = min(runs, key=lambda run: (not run.successful, run.current.cost()))
    return _report(fit, train, best, runs, t_start, first_eval_s)


# ------------------------------------------------------------------------------ the problem
@dataclasses.dataclass(frozen=True)
class _Fit:
    """The set-up of one fit: the checked frames and the problem on them."""

    scene: Scene  # the user's scene, with zero stiffening laws where they are fitted
    dataset: MocapDataset
    validation: MocapDataset | None
    problem: Problem
    labels: list  # per block: the labels of its reported values
    # The starting mocap transform (given, identity, or aligned at the start), kept as numpy:
    # the report's initial values.
    rotation0: np.ndarray
    translation0: np.ndarray
    noise: float
    bounds: tuple  # (lower, upper) of the internal coordinates

    @property
    def orient(self) -> bool:
        """The training frames carry orientations (the residuals have orientation terms)."""
        return self.dataset.orientations is not None

    @property
    def n_observations(self) -> int:
        """Observed marker coordinates and orientation components of the training frames."""
        d = self.dataset
        n = d.observed.sum() * 3
        if self.orient:
            n = n + np.isfinite(d.orientations.reshape(d.n_frames, -1, 9)).all(-1).sum() * 3
        return int(n)

    def evaluator(self, data: MocapDataset, chunk: int, options: dict) -> Evaluator:
        """Warm-started batch evaluation of the frames of ``data`` (padded to whole chunks)."""
        frames = FrameData.build(data, self.problem.frame_loads, chunk, self.orient)
        return Evaluator(self.problem, frames, chunk, options)


def _build_problem(
    scene: Scene,
    dataset,
    validation,
    params,
    per_segment,
    mocap_transform,
    scales,
    bounds=None,
    frame_update=None,
) -> _Fit:
    """The parameter blocks, frame loads, starting transform and residual scales ``(noise,
    orientation_noise, huber_delta or None for the quadratic loss)`` of a fit on ``dataset``;
    raises where ``validation`` carries other kinds of data."""
    fit_scene, blocks, initial, labels = make_blocks(scene, params, per_segment, dataset.n_markers)
    loaded, frame_loads = with_frame_loads(fit_scene, dataset, frame_update)
    if validation is not None:
        _check_validation_kinds(fit_scene, dataset, validation, frame_update)
    rot0, trans0 = _starting_transform(mocap_transform)
    noise, orientation_noise, huber_delta = scales
    sites = dataset.sites
    offsets0 = np.asarray([x[2] for x in sites], float)
    problem = Problem(
        scene=loaded,
        frame_loads=frame_loads,
        blocks=tuple(blocks),
        initial=tuple(
            offsets0 if b.name == "marker_offsets" else (None if v is None else jnp.asarray(v))
            for b, v in zip(blocks, initial, strict=True)
        ),
        rotation0=jnp.asarray(rot0),
        translation0=jnp.asarray(trans0),
        site_segment=tuple(int(x[0]) for x in sites),
        site_s=tuple(float(x[1]) for x in sites),
        offsets=jnp.asarray(offsets0),
        noise=jnp.asarray(float(noise)),
        orientation_noise=jnp.asarray(float(orientation_noise)),
        huber_delta=jnp.asarray(L2_DELTA if huber_delta is None else float(huber_delta)),
    )
    bounds = theta_bounds(blocks, initial, bounds)
    return _Fit(fit_scene, dataset, validation, problem, labels, rot0, trans0, float(noise), bounds)


def _check_validation_kinds(fit_scene: Scene, dataset, validation, frame_update) -> None:
    """Raise unless ``validation`` carries the loads and orientations ``dataset`` does."""
    with_frame_loads(fit_scene, validation, frame_update)  # same checks
    kinds = ("payload_mass", "force", "base_rotation", "gravity_direction", "frame_values")
    if any((getattr(validation, k) is None) != (getattr(dataset, k) is None) for k in kinds):
        raise ValueError(
            "validation must carry the same kinds of per-frame data (loads, base and gravity "
            "directions, frame values) as dataset"
        )
    if dataset.orientations is not None and validation.orientations is None:
        raise ValueError("dataset has orientations but validation does not")


def _starting_transform(mocap_transform) -> tuple[np.ndarray, np.ndarray]:
    """The checked ``(rotation, translation)`` given, or the identity."""
    if mocap_transform is None:
        return np.eye(3), np.zeros(3)
    rot0, trans0 = (np.asarray(x, float) for x in mocap_transform)
    if rot0.shape != (3, 3) or trans0.shape != (3,):
        raise ValueError("mocap_transform must be (rotation (3, 3), translation (3,))")
    if not np.allclose(rot0.T @ rot0, np.eye(3), atol=1e-6) or np.linalg.det(rot0) < 0:
        raise ValueError("mocap_transform rotation must be a proper rotation matrix")
    return rot0, trans0


def _batch_settings(chunk_size, options: SolverOptions | None) -> tuple[int, dict]:
    """Frames per compiled batch, and the keyword arguments of the frames' solve_batch."""
    chunk = int(chunk_size)
    if chunk < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    # A frame that fails at a trial point rejects the step; the diffrax fallback (a long
    # compilation) is only used when asked for.
    return chunk, {"fallback": False, "options": resolve_options(options)}


# ------------------------------------------------------------------------------ the fit
def _start(fit: _Fit, train: Evaluator, theta, align: bool):
    """The first evaluation, at the starting values ``theta``. With ``align``, the starting
    mocap transform becomes the rigid alignment (Kabsch) of the starting model's markers to the
    data, and the frames are evaluated again. Returns ``(fit, evaluation, first evaluation's
    time in s)``."""
    t0 = time.perf_counter()
    current = train(theta)
    first_eval_s = time.perf_counter() - t0
    if not current.valid[: fit.dataset.n_frames].any():
        raise ValueError("no training frame converged to a stable equilibrium at the start values")
    if align:
        world = (current.pred - fit.translation0) @ fit.rotation0  # predictions, world frame
        rot0, trans0 = kabsch(world, fit.dataset.markers)
        problem = dataclasses.replace(
            fit.problem, rotation0=jnp.asarray(rot0), translation0=jnp.asarray(trans0)
        )
        fit = dataclasses.replace(fit, problem=problem, rotation0=rot0, translation0=trans0)
        train.problem = problem
        current = train(theta, q0=current.q)
    return fit, current, first_eval_s


def _report(fit: _Fit, train, best: Descent, runs: list, t_start, first_eval_s):
    """The fitted scene and the :class:`IdentificationReport` of the best descent."""
    problem = fit.problem
    theta, current = best.theta, best.current
    cov, std_theta = covariance(current, fit.n_observations, problem.n_theta)
    fitted, rot, trans, offsets = problem.apply(jnp.asarray(theta))
    parameters, names, identifiable = parameter_table(
        problem, fit.labels, fit.bounds, fit.translation0, theta, std_theta, trans
    )
    tip = int(np.argmax([seg + s for seg, s, _ in fit.dataset.sites]))
    errors_train = _fit_errors(current, fit.dataset, tip, fit.orient)
    errors_val = None
    if fit.validation is not None:
        held = fit.evaluator(fit.validation, train.chunk, train.options)
        errors_val = _fit_errors(held(theta), fit.validation, tip, fit.orient)
    out_scene = _fitted_scene(fitted, fit.scene, fit.dataset.sites, offsets)
    iterations, result, message = best.stop
    report = IdentificationReport(
        parameters=parameters,
        loss_history=best.history.losses,
        rmse_history_mm=best.history.rmse,
        train=errors_train,
        validation=errors_val,
        rotation=np.asarray(rot),
        translation=np.asarray(trans),
        iterations=iterations,
        evaluations=train.count,
        result=result,
        message=message,
        covariance=cov,
        coordinate_names=names,
        identifiable=identifiable,
        time_s=time.perf_counter() - t_start,
        first_evaluation_s=first_eval_s,
        noise=fit.noise,
        branches=best.branches,
        starts=[run_summary(run, fit.n_observations) for run in runs] if len(runs) > 1 else None,
    )
    return out_scene, report


def _staged(scene: Scene, dataset: MocapDataset, stages, settings: dict, t_start: float):
    """Fits of each stage's parameters in turn, each from the last one's values."""
    stages = [list(stage) for stage in stages]
    if not stages or not all(stages):
        raise ValueError("stages must be a non-empty list of non-empty parameter lists")
    for k, params in enumerate(stages):  # every stage's names before the first fit
        try:
            per = [p for p in settings["per_segment"] if p in params]
            check_params(params, per)
        except ValueError as err:
            raise ValueError(f"stages[{k}]: {err}") from None
    summaries, losses, rmse, evaluations = [], [], [], 0
    for params in stages:
        fitted = set(params)
        stage = dict(settings)
        stage["per_segment"] = [p for p in settings["per_segment"] if p in fitted]
        for key in ("bounds", "priors"):
            given = settings[key] or {}
            stage[key] = {p: v for p, v in given.items() if p in fitted} or None
        scene, report = identify(scene, dataset, params, **stage)
        if "mocap_transform" in fitted:
            settings["mocap_transform"] = (report.rotation, report.translation)
        if "marker_offsets" in fitted:
            dataset = dataclasses.replace(dataset, sites=scene.markers)
        summaries.append(
            {
                "params": params,
                "loss": report.loss_history[-1],
                "rmse_mm": report.rmse_history_mm[-1],
                "iterations": report.iterations,
                "message": report.message,
            }
        )
        losses += report.loss_history
        rmse += report.rmse_history_mm
        evaluations += report.evaluations
    report = dataclasses.replace(
        report,
        loss_history=losses,
        rmse_history_mm=rmse,
        evaluations=evaluations,
        stages=summaries,
        time_s=time.perf_counter() - t_start,
    )
    return scene, report


def _fit_errors(evaluation, data: MocapDataset, tip: int, orient: bool) -> FitErrors:
    n = data.n_frames
    return FitErrors.compute(
        evaluation.pred,
        data.markers,
        tip,
        evaluation.valid[:n],
        evaluation.q[:n],
        evaluation.rpred if orient else None,
        data.orientations,
    )


def _fitted_scene(fitted: Scene, fit_scene: Scene, sites, offsets) -> Scene:
    """The fitted scene: the user's structure (no per-frame loads), fitted marker offsets."""
    return fitted.replace(
        loads=fit_scene.loads,
        markers=tuple(
            (seg, s, tuple(float(v) for v in off))
            for (seg, s, _), off in zip(sites, np.asarray(offsets), strict=True)
        ),
        quadrature_points=fit_scene.quadrature_points,
        rotation_substeps=fit_scene.rotation_substeps,
        knot_grid=fit_scene.knot_grid,
    )
