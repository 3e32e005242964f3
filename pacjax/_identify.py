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

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from ._batch import solve_batch
from ._fitreport import FitErrors, IdentificationReport
from ._frameloads import FrameLoads, with_frame_loads
from ._mocap import MocapDataset
from ._robot import ExponentialStiffening
from ._rotation import exp_so3, matvec3
from ._scene import Scene, normalise_sites

#: name -> (what it is, unit, positive)
PARAMETERS = {
    "bending_stiffness": ("segment", "N m^2", True),
    "axial_stiffness": ("segment", "N/m", True),
    "torsion_stiffness": ("segment", "N m^2", True),
    "linear_density": ("segment", "kg/m", True),
    "stiffening": ("segment", "1", False),
    "tendon_gain": ("tendon", "N/m", True),
    "tendon_offset": ("tendon", "m", True),
    "mocap_transform": ("transform", "rad | m", False),
    "marker_offsets": ("marker", "m", False),
}
_STEP_SCALE = {"stiffening": 1.0, "mocap_transform": 1.0, "marker_offsets": 0.01}


class _Block(eqx.Module):
    """One fitted parameter group (static description)."""

    name: str = eqx.field(static=True)
    size: int = eqx.field(static=True)  # internal coordinates
    targets: tuple = eqx.field(static=True)  # segment / tendon / marker indices written
    log: bool = eqx.field(static=True)


class _Problem(eqx.Module):
    """Everything the compiled residual needs; equal structure means no recompilation."""

    scene: Scene
    frame_loads: FrameLoads = eqx.field(static=True)
    blocks: tuple = eqx.field(static=True)
    initial: tuple  # physical starting values per block (arrays)
    rotation0: jax.Array
    translation0: jax.Array
    site_segment: tuple = eqx.field(static=True)
    site_s: tuple = eqx.field(static=True)
    offsets: jax.Array  # (m, 3) starting marker stand-offs
    noise: jax.Array
    orientation_noise: jax.Array
    huber_delta: jax.Array
    robust: bool = eqx.field(static=True)

    @property
    def n_theta(self) -> int:
        return sum(b.size for b in self.blocks)

    def split(self, theta):
        out, k = [], 0
        for b in self.blocks:
            out.append(theta[k : k + b.size])
            k += b.size
        return out

    def physical(self, block: _Block, init, th):
        if block.name == "mocap_transform":
            return th
        if block.name == "marker_offsets":
            return init + _STEP_SCALE["marker_offsets"] * th.reshape(init.shape)
        if block.log:
            return init * jnp.exp(th)  # th broadcasts when shared
        return init + _STEP_SCALE.get(block.name, 1.0) * th

    def apply(self, theta):
        """``(scene, rotation, translation, offsets)`` at internal coordinates ``theta``."""
        scene, rot, trans, offsets = self.scene, self.rotation0, self.translation0, self.offsets
        for block, init, th in zip(self.blocks, self.initial, self.split(theta), strict=True):
            value = self.physical(block, init, th)
            if block.name == "mocap_transform":
                rot = exp_so3(value[:3]) @ self.rotation0
                trans = self.translation0 + value[3:]
            elif block.name == "marker_offsets":
                offsets = value
            else:
                scene = _put(scene, block, value)
        return scene, rot, trans, offsets


def _put(scene: Scene, block: _Block, value) -> Scene:
    idx = block.targets
    name = block.name
    if name == "stiffening":
        where = lambda s: [s.robot.segments[i].stiffening.rate for i in idx]  # noqa: E731
    elif PARAMETERS[name][0] == "segment":
        where = lambda s: [getattr(s.robot.segments[i], name) for i in idx]  # noqa: E731
    elif name == "tendon_gain":
        where = lambda s: [s.tendons[i].gain for i in idx]  # noqa: E731
    else:  # tendon_offset: the offset, and a tapered route's end offset in proportion
        ends = [i for i in idx if scene.tendons[i].offset_end is not None]
        ratio = {i: scene.tendons[i].offset_end / scene.tendons[i].offset for i in ends}
        scene = eqx.tree_at(
            lambda s: [s.tendons[i].offset_end for i in ends],
            scene,
            [value[idx.index(i)] * ratio[i] for i in ends],
        )
        where = lambda s: [s.tendons[i].offset for i in idx]  # noqa: E731
    return eqx.tree_at(where, scene, [value[k] for k in range(len(idx))])


def _frame_residual(problem: _Problem, theta, q, controls, row, meas, mask, rmeas, rmask):
    """Scaled residuals of one frame (robust weights applied), predictions, and the scene's
    equilibrium residual function's ingredients."""
    scene, rot, trans, offsets = problem.apply(theta)
    if row is not None:
        scene = problem.frame_loads(scene, row)
    frames_rot, frames_pos = scene.frames(
        q, np.asarray(problem.site_segment), jnp.asarray(problem.site_s, q.dtype)
    )
    world = frames_pos + matvec3(frames_rot, offsets)
    pred = world @ rot.T + trans
    d = (pred - meas) / problem.noise * mask[:, None]
    if problem.robust:
        e2 = jnp.sum(d * d, -1)
        big = e2 > problem.huber_delta**2
        e = jnp.sqrt(jnp.where(big, e2, 1.0))
        w = jnp.where(big, jnp.sqrt(2.0 * optax.huber_loss(e, delta=problem.huber_delta)) / e, 1.0)
        d = d * w[:, None]
    parts = [d.reshape(-1)]
    rpred = jnp.einsum("ij,mjk->mik", rot, frames_rot)
    if rmeas is not None:
        rel = jnp.einsum("mji,mjk->mik", rpred, rmeas)
        skew = 0.5 * (rel - jnp.swapaxes(rel, -1, -2))
        v = jnp.stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]], -1)
        parts.append((v / problem.orientation_noise * rmask[:, None]).reshape(-1))
    return jnp.concatenate(parts), pred, rpred


def _frame_jacobian(problem, theta, q, controls, row, meas, mask, rmeas, rmask):
    """Residuals and their total derivative by the implicit function theorem."""

    def equilibrium_residual(th, q_):
        scene = problem.apply(th)[0]
        if row is not None:
            scene = problem.frame_loads(scene, row)
        return scene.residual(q_, controls)

    def residual(th, q_):
        return _frame_residual(problem, th, q_, controls, row, meas, mask, rmeas, rmask)

    r, pred, rpred = residual(theta, q)
    d_theta = jax.jacfwd(lambda th: residual(th, q)[0])(theta)
    d_q = jax.jacfwd(lambda q_: residual(theta, q_)[0])(q)
    stiffness = jax.jacfwd(equilibrium_residual, 1)(theta, q)
    forcing = jax.jacfwd(equilibrium_residual, 0)(theta, q)
    dq = -jnp.linalg.solve(stiffness, forcing)  # implicit function theorem
    return r, d_theta + d_q @ dq, pred, rpred


@eqx.filter_jit
def _evaluate(problem, theta, q, controls, rows, meas, mask, rmeas, rmask):
    axes = (None, None, 0, 0, 0 if rows is not None else None, 0, 0)
    axes += (0 if rmeas is not None else None, 0 if rmask is not None else None)
    return jax.vmap(_frame_jacobian, in_axes=axes)(
        problem, theta, q, controls, rows, meas, mask, rmeas, rmask
    )


# ------------------------------------------------------------------------------ set-up
def _blocks(scene: Scene, params, per_segment, n_markers) -> tuple[Scene, list, list, list]:
    """Blocks, starting values and labels; adds zero stiffening laws where they are fitted."""
    if isinstance(params, str):
        params = (params,)
    params = tuple(params)
    if not params:
        raise ValueError("params is empty: name at least one parameter to fit")
    for name in params + tuple(per_segment):
        if name not in PARAMETERS:
            raise ValueError(f"unknown parameter {name!r}; known: {', '.join(PARAMETERS)}")
    if len(set(params)) != len(params):
        raise ValueError(f"params lists a parameter twice: {params}")
    for name in per_segment:
        if name not in params:
            raise ValueError(f"per_segment names {name!r}, which is not in params")
        if PARAMETERS[name][0] not in ("segment", "tendon"):
            raise ValueError(f"per_segment applies to segment and tendon parameters, not {name!r}")
    if "stiffening" in params:
        segments = [
            seg
            if seg.stiffening is not None
            else dataclasses.replace(seg, stiffening=ExponentialStiffening(0.0))
            for seg in scene.robot.segments
        ]
        if not all(isinstance(seg.stiffening, ExponentialStiffening) for seg in segments):
            raise ValueError("stiffening can be fitted for ExponentialStiffening laws only")
        scene = eqx.tree_at(lambda s: s.robot.segments, scene, tuple(segments))
    blocks, initial, labels = [], [], []
    for name in params:
        kind, unit, positive = PARAMETERS[name]
        per = name in per_segment
        if kind == "segment":
            idx = tuple(range(scene.n_segments))
            if name == "stiffening":
                values = [float(seg.stiffening.rate) for seg in scene.robot.segments]
            else:
                values = [float(getattr(seg, name)) for seg in scene.robot.segments]
            label = [f"[{i}]" for i in idx]
        elif kind == "tendon":
            idx = tuple(
                i
                for i, t in enumerate(scene.tendons)
                if name != "tendon_gain" or t.mode == "length"
            )
            if not idx:
                raise ValueError(
                    f"{name}: the scene has no "
                    + (
                        "length-mode tendon (tension-mode tendons have no gain)"
                        if scene.tendons and name == "tendon_gain"
                        else "tendon"
                    )
                )
            attr = "gain" if name == "tendon_gain" else "offset"
            values = [float(getattr(scene.tendons[i], attr)) for i in idx]
            label = [f"[{i}]" for i in idx]
        elif kind == "transform":
            idx, values = (), [0.0] * 6
            label = ["[rx]", "[ry]", "[rz]", "[tx]", "[ty]", "[tz]"]
        else:
            idx, values = tuple(range(n_markers)), None
            label = [f"[{j}].{a}" for j in range(n_markers) for a in "xyz"]
        if positive and any(v <= 0 for v in values):
            raise ValueError(
                f"{name}: the starting value must be > 0 to fit it (log scale), got {values}"
            )
        if kind in ("segment", "tendon"):
            size = len(idx) if per else 1
        elif kind == "transform":
            size = 6
        else:
            size = 3 * n_markers
        blocks.append(_Block(name, size, idx, positive))
        initial.append(None if values is None else np.asarray(values, float))
        labels.append(
            label
            if (per or kind not in ("segment", "tendon"))
            else ([""] if len(set(values)) == 1 else label)
        )
    return scene, blocks, initial, labels


def _check(scene: Scene, dataset: MocapDataset, name: str) -> None:
    if not isinstance(dataset, MocapDataset):
        raise TypeError(f"{name} must be a pacjax.MocapDataset, got {type(dataset).__name__}")
    if dataset.n_controls != scene.n_tendons:
        raise ValueError(
            f"{name} has {dataset.n_controls} control column(s) but the scene has "
            f"{scene.n_tendons} tendon(s)"
        )
    normalise_sites(dataset.sites, scene.n_segments, f"{name}.sites")
    for i, t in enumerate(scene.tendons):
        if t.mode == "tension" and np.any(dataset.controls[:, i] < 0):
            raise ValueError(f"{name}.controls[:, {i}] are tensions and must be >= 0")


def _check_variation(dataset: MocapDataset) -> None:
    if dataset.n_frames < 2:
        return
    cond = dataset.conditions()
    if np.all(cond == cond[0]):
        raise ValueError(
            "every training frame has the same controls and loads (no variation): the data "
            "cannot separate the parameters; record poses under different commands or payloads"
        )
    m = dataset.markers
    spread = np.nanmax(np.nanmax(m, 0) - np.nanmin(m, 0))
    if spread == 0.0:
        raise ValueError(
            "the markers are identical in every frame although the controls change: the marker "
            "columns look frozen or mismatched"
        )


def _kabsch(world: np.ndarray, measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation and translation with ``measured ~ R world + t`` (observed points only)."""
    ok = np.isfinite(measured).all(-1)
    a, b = world[ok], measured[ok]
    ca, cb = a.mean(0), b.mean(0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, cb - r @ ca


@dataclasses.dataclass
class _Data:
    """A dataset padded to whole chunks, as arrays for the compiled evaluation."""

    n: int
    controls: np.ndarray
    rows: dict | None
    meas: np.ndarray
    mask: np.ndarray
    rmeas: np.ndarray | None
    rmask: np.ndarray | None
    q: np.ndarray | None = None  # warm starts

    @staticmethod
    def build(dataset: MocapDataset, frame_loads: FrameLoads, chunk: int, orient: bool):
        n = dataset.n_frames
        total = -(-n // chunk) * chunk

        def pad(x):
            return None if x is None else np.concatenate([x, np.repeat(x[-1:], total - n, 0)])

        mask = dataset.observed.astype(float)
        mask = np.concatenate([mask, np.zeros((total - n,) + mask.shape[1:])])
        meas = pad(np.nan_to_num(dataset.markers))
        rows = frame_loads.rows(dataset)
        rows = None if rows is None else {k: pad(v) for k, v in rows.items()}
        rmeas = rmask = None
        if orient:
            ori = dataset.orientations
            ok = np.isfinite(ori.reshape(n, dataset.n_markers, 9)).all(-1)
            rmask = np.concatenate([ok.astype(float), np.zeros((total - n, ok.shape[1]))])
            rmeas = pad(np.where(ok[..., None, None], ori, np.eye(3)))
        return _Data(n, pad(dataset.controls), rows, meas, mask, rmeas, rmask)


class _Evaluator:
    """Batch equilibria (warm-started) and residual Jacobians of one dataset."""

    def __init__(self, problem, data: _Data, chunk: int, solver_options: dict):
        self.problem, self.data, self.chunk, self.options = problem, data, chunk, solver_options
        self.count = 0

    def __call__(self, theta, q0=None):
        p, d = self.problem, self.data
        scene = p.apply(jnp.asarray(theta))[0]
        update = p.frame_loads if d.rows is not None else None
        eq = solve_batch(
            scene,
            d.controls,
            q0=q0,
            params=d.rows,
            update=update,
            chunk_size=self.chunk,
            progress=False,
            **self.options,
        )
        q = np.asarray(eq.q)
        ok = np.asarray(eq.converged) & np.asarray(eq.stable) & np.all(np.isfinite(q), 1)
        q_safe = np.where(ok[:, None], q, 0.0)
        rs, js, preds, rpreds = [], [], [], []
        for start in range(0, len(q), self.chunk):
            sl = slice(start, start + self.chunk)
            pick = lambda x, sl=sl: None if x is None else jnp.asarray(x[sl])  # noqa: E731
            rows = None if d.rows is None else {k: jnp.asarray(v[sl]) for k, v in d.rows.items()}
            r, j, pred, rpred = _evaluate(
                p,
                jnp.asarray(theta),
                pick(q_safe),
                pick(d.controls),
                rows,
                pick(d.meas),
                pick(d.mask),
                pick(d.rmeas),
                pick(d.rmask),
            )
            rs.append(np.asarray(r))
            js.append(np.asarray(j))
            preds.append(np.asarray(pred))
            rpreds.append(np.asarray(rpred))
        self.count += 1
        valid = ok.copy()
        valid[d.n :] = False
        r = np.concatenate(rs) * valid[:, None]
        j = np.concatenate(js) * valid[:, None, None]
        return _Eval(r, j, np.concatenate(preds)[: d.n], np.concatenate(rpreds)[: d.n], q, valid)


@dataclasses.dataclass
class _Eval:
    r: np.ndarray  # (frames, k)
    j: np.ndarray  # (frames, k, p)
    pred: np.ndarray
    rpred: np.ndarray
    q: np.ndarray
    valid: np.ndarray

    def cost(self, valid=None) -> float:
        v = self.valid if valid is None else valid
        return 0.5 * float(np.sum(self.r[v] ** 2))


def identify(
    scene: Scene,
    dataset: MocapDataset,
    params: Sequence[str] = ("bending_stiffness",),
    *,
    per_segment: Sequence[str] = (),
    validation: MocapDataset | None = None,
    holdout: float = 0.0,
    seed: int = 0,
    mocap_transform=None,
    noise: float = 1e-3,
    orientation_noise: float = np.radians(1.0),
    loss: str = "l2",
    huber_delta: float = 3.0,
    optimizer="levenberg-marquardt",
    max_iterations: int = 50,
    tol: float = 1e-10,
    chunk_size: int = 32,
    progress: bool | None = None,
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
            ``marker_offsets`` (each marker's stand-off from the backbone, local frame).
            Segment and tendon parameters are one shared factor on the starting values, or one
            value per segment / tendon when named in ``per_segment``.
        validation: held-out frames (or ``holdout``: a random fraction of ``dataset``).
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
        chunk_size: frames per compiled batch (every dataset is padded to whole chunks, so
            train and held-out frames share one compilation).
        progress: show a tqdm progress bar (default: when stderr is a terminal).
        solver_options: keyword arguments for :func:`pacjax.solve_batch` (default
            ``fallback=False``).

    Returns:
        ``(fitted_scene, report)``: the scene with the fitted values (and fitted marker
        offsets), and an :class:`IdentificationReport`.
    """
    t_start = time.perf_counter()
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a pacjax.Scene, got {type(scene).__name__}")
    _check(scene, dataset, "dataset")
    if validation is not None and holdout:
        raise ValueError("give either validation= or holdout=, not both")
    if holdout:
        dataset, validation = dataset.split(holdout, seed)
    if validation is not None:
        _check(scene, validation, "validation")
        if validation.sites != dataset.sites:
            raise ValueError("validation must have the same marker sites as dataset")
    _check_variation(dataset)
    if loss not in ("l2", "huber"):
        raise ValueError(f"loss must be 'l2' or 'huber', got {loss!r}")
    if not noise > 0 or not orientation_noise > 0 or not huber_delta > 0:
        raise ValueError("noise, orientation_noise and huber_delta must be > 0")
    if max_iterations < 0:
        raise ValueError(f"max_iterations must be >= 0, got {max_iterations}")
    lm = isinstance(optimizer, str)
    if lm and optimizer != "levenberg-marquardt":
        raise ValueError(
            f"optimizer must be 'levenberg-marquardt' or an optax optimiser, got {optimizer!r}"
        )
    if not lm and not isinstance(optimizer, optax.GradientTransformation):
        raise TypeError(
            "optimizer must be 'levenberg-marquardt' or an optax.GradientTransformation"
        )

    fitting_transform = "mocap_transform" in params
    fit_scene, blocks, initial, labels = _blocks(scene, params, per_segment, dataset.n_markers)
    loaded, frame_loads = with_frame_loads(fit_scene, dataset)
    if validation is not None:
        with_frame_loads(fit_scene, validation)  # same checks
        if (validation.payload_mass is None) != (dataset.payload_mass is None) or (
            validation.force is None
        ) != (dataset.force is None):
            raise ValueError("validation must carry the same kinds of loads as dataset")
    sites = dataset.sites
    orient = dataset.orientations is not None
    if validation is not None and orient and validation.orientations is None:
        raise ValueError("dataset has orientations but validation does not")
    if mocap_transform is not None:
        rot0, trans0 = (np.asarray(x, float) for x in mocap_transform)
        if rot0.shape != (3, 3) or trans0.shape != (3,):
            raise ValueError("mocap_transform must be (rotation (3, 3), translation (3,))")
        if not np.allclose(rot0.T @ rot0, np.eye(3), atol=1e-6) or np.linalg.det(rot0) < 0:
            raise ValueError("mocap_transform rotation must be a proper rotation matrix")
    else:
        rot0, trans0 = np.eye(3), np.zeros(3)
    offsets0 = np.asarray([x[2] for x in sites], float)
    problem = _Problem(
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
        huber_delta=jnp.asarray(float(huber_delta)),
        robust=loss == "huber",
    )
    chunk = max(
        1, min(chunk_size, max(dataset.n_frames, 0 if validation is None else validation.n_frames))
    )
    # A frame that fails at a trial point rejects the step; the diffrax fallback (a long
    # compilation) is only used when asked for.
    options = {"fallback": False, **(solver_options or {})}
    train = _Evaluator(problem, _Data.build(dataset, frame_loads, chunk, orient), chunk, options)
    theta = np.zeros(problem.n_theta)

    t0 = time.perf_counter()
    current = train(theta)
    first_eval_s = time.perf_counter() - t0
    if not current.valid[: dataset.n_frames].any():
        raise ValueError("no training frame converged to a stable equilibrium at the start values")
    if fitting_transform and mocap_transform is None:
        world = (current.pred - trans0) @ rot0  # predictions in the world frame
        rot0, trans0 = _kabsch(world, dataset.markers)
        problem = dataclasses.replace(
            problem, rotation0=jnp.asarray(rot0), translation0=jnp.asarray(trans0)
        )
        train.problem = problem
        current = train(theta, q0=current.q)

    n_obs = int(
        dataset.observed.sum() * 3
        + (
            0
            if not orient
            else np.isfinite(dataset.orientations.reshape(dataset.n_frames, -1, 9)).all(-1).sum()
            * 3
        )
    )
    losses = [current.cost() / n_obs]
    rmse = [_rmse_mm(current.pred, dataset.markers)]
    from tqdm.auto import tqdm

    bar = tqdm(
        total=max_iterations,
        desc="identify",
        unit="it",
        disable=None if progress is None else not progress,
        leave=False,
    )
    converged, message = False, "iteration limit reached"
    iterations = 0
    if lm:
        damping, rejected = 1e-3, 0
        while iterations < max_iterations:
            r = current.r[current.valid].reshape(-1)
            jac = current.j[current.valid].reshape(r.size, -1)
            jtj, g = jac.T @ jac, jac.T @ r
            diag = np.maximum(np.diag(jtj), 1e-12 * max(np.max(np.diag(jtj)), 1e-300))
            step = np.linalg.solve(jtj + damping * np.diag(diag), -g)
            predicted = -(g @ step + 0.5 * step @ jtj @ step)  # decrease of the linear model
            if predicted <= tol * current.cost():
                converged, message = True, "converged (no decrease left to gain)"
                break
            trial = train(theta + step, q0=current.q)
            ok = bool(np.all(trial.valid[current.valid]))
            if ok and trial.cost(current.valid) < current.cost():
                decrease = (current.cost() - trial.cost(current.valid)) / max(
                    current.cost(), 1e-300
                )
                theta, current = theta + step, trial
                iterations += 1
                damping, rejected = max(damping / 3.0, 1e-12), 0
                losses.append(current.cost() / n_obs)
                rmse.append(_rmse_mm(current.pred, dataset.markers))
                bar.update()
                bar.set_postfix_str(f"RMSE {rmse[-1]:.3f} mm")
                if np.max(np.abs(step)) < np.sqrt(tol) or decrease < tol:
                    converged, message = True, "converged (step or loss change below tolerance)"
                    break
            else:
                damping, rejected = damping * 4.0, rejected + 1
                if rejected >= 5:
                    converged = ok
                    message = (
                        "converged (no step reduces the loss further: at the solver's accuracy)"
                        if ok
                        else "stopped: equilibria fail to converge along every trial step"
                    )
                    break
    else:
        state = optimizer.init(theta)
        while iterations < max_iterations:
            r = current.r[current.valid].reshape(-1)
            grad = current.j[current.valid].reshape(r.size, -1).T @ r
            updates, state = optimizer.update(grad, state, theta)
            new_theta = np.asarray(optax.apply_updates(theta, updates))
            trial = train(new_theta, q0=current.q)
            if not np.all(trial.valid[current.valid]):
                message = "stopped: a frame failed to converge along the optax path"
                break
            previous = current.cost()
            theta, current = new_theta, trial
            iterations += 1
            losses.append(current.cost() / n_obs)
            rmse.append(_rmse_mm(current.pred, dataset.markers))
            bar.update()
            bar.set_postfix_str(f"RMSE {rmse[-1]:.3f} mm")
            if abs(previous - current.cost()) < tol * max(previous, 1e-300):
                converged, message = True, "converged (loss change below tolerance)"
                break
    bar.close()

    # Laplace / Gauss-Newton covariance at the optimum.
    r = current.r[current.valid].reshape(-1)
    jac = current.j[current.valid].reshape(r.size, -1)
    dof = max(n_obs - problem.n_theta, 1)
    s2 = float(r @ r) / dof
    cov = s2 * np.linalg.pinv(jac.T @ jac)
    std_theta = np.sqrt(np.maximum(np.diag(cov), 0.0))

    _, rot, trans, offsets = problem.apply(jnp.asarray(theta))
    parameters, names, identifiable = {}, [], []
    k = 0
    for block, init, label, th in zip(
        blocks, problem.initial, labels, problem.split(theta), strict=True
    ):
        sd = std_theta[k : k + block.size]
        k += block.size
        kind, unit, positive = PARAMETERS[block.name]
        if block.name == "mocap_transform":
            value = np.concatenate([np.asarray(th[:3]), np.asarray(trans)])
            start = np.concatenate([np.zeros(3), trans0])
            std = sd
        else:
            value = np.asarray(problem.physical(block, init, jnp.asarray(th)), float).reshape(-1)
            start = np.asarray(init, float).reshape(-1)
            scale = value if block.log else np.full(value.shape, _STEP_SCALE.get(block.name, 1.0))
            std = np.abs(scale) * (sd if block.size == value.size else sd[0])
        if len(label) == 1 and value.size > 1:  # one shared factor on equal values
            value, start, std = value[:1], start[:1], std[:1]
        rel = [float(s / abs(v)) if v != 0 else None for s, v in zip(std, value, strict=True)]
        parameters[block.name] = {
            "unit": unit,
            "labels": list(label),
            "initial": [float(v) for v in start],
            "value": [float(v) for v in value],
            "std": [float(v) if np.isfinite(v) else None for v in std],
            "relative_std": rel,
        }
        if block.size == len(label):
            names += [f"{block.name}{x}" for x in label]
        else:
            names += (
                [block.name]
                if block.size == 1
                else [f"{block.name}[{i}]" for i in range(block.size)]
            )
        # A log-coordinate with a standard deviation above 1 is not pinned down by the data.
        identifiable += [bool(s < 1.0) if block.log else True for s in sd]

    tip = int(np.argmax([seg + s for seg, s, _ in sites]))
    errors_train = FitErrors.compute(
        current.pred,
        dataset.markers,
        tip,
        current.valid[: dataset.n_frames],
        current.q[: dataset.n_frames],
        current.rpred if orient else None,
        dataset.orientations,
    )
    errors_val = None
    if validation is not None:
        held = _Evaluator(
            problem, _Data.build(validation, frame_loads, chunk, orient), chunk, options
        )
        ev = held(theta)
        errors_val = FitErrors.compute(
            ev.pred,
            validation.markers,
            tip,
            ev.valid[: validation.n_frames],
            ev.q[: validation.n_frames],
            ev.rpred if orient else None,
            validation.orientations,
        )
    # The fitted scene: the user's structure (no per-frame loads), fitted marker offsets.
    out_scene = problem.apply(jnp.asarray(theta))[0]
    out_scene = Scene(
        out_scene.robot,
        out_scene.model,
        tendons=out_scene.tendons,
        loads=fit_scene.loads,
        markers=tuple(
            (seg, s, tuple(float(v) for v in off))
            for (seg, s, _), off in zip(sites, np.asarray(offsets), strict=True)
        ),
        quadrature_points=fit_scene.quadrature_points,
        rotation_substeps=fit_scene.rotation_substeps,
    )
    report = IdentificationReport(
        parameters=parameters,
        loss_history=losses,
        rmse_history_mm=rmse,
        train=errors_train,
        validation=errors_val,
        rotation=np.asarray(rot),
        translation=np.asarray(trans),
        iterations=iterations,
        evaluations=train.count,
        converged=converged,
        message=message,
        covariance=cov,
        coordinate_names=names,
        identifiable=identifiable,
        time_s=time.perf_counter() - t_start,
        first_evaluation_s=first_eval_s,
        noise=float(noise),
    )
    return out_scene, report


def _rmse_mm(pred: np.ndarray, measured: np.ndarray) -> float:
    d = np.linalg.norm(pred - measured, axis=-1)
    return float(1e3 * np.sqrt(np.nanmean(d**2)))
