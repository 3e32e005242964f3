"""The evaluation of a dataset in :func:`pacjax.identify`: every frame's equilibrium (a
warm-started batch), its marker residuals and their total derivative along the equilibria by
the implicit function theorem, and the scattered-start solves of the branch checks.

The compiled parts take the :class:`pacjax._identify.problem.Problem` as an argument: equal
structure means no recompilation across fits.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import optax

from .._config import MATMUL_PRECISION
from .._jit import jit
from .._model.frameloads import FrameLoads
from .._model.rotation import matvec3
from .._statics.batch import solve_batch
from .dataset import MocapDataset
from .problem import Problem


def _frame_markers(problem: Problem, theta, q, row):
    """Marker predictions (mocap frame) of one frame, the site rotations (world) and the mocap
    frame's rotation."""
    scene, rot, trans, offsets = problem.apply(theta)
    if row is not None:
        scene = problem.frame_loads(scene, row)
    frames_rot, frames_pos = scene.frames(
        q, np.asarray(problem.site_segment), jnp.asarray(problem.site_s, q.dtype)
    )
    world = frames_pos + matvec3(frames_rot, offsets)
    return jnp.matmul(world, rot.T, precision=MATMUL_PRECISION) + trans, frames_rot, rot


def _frame_residual(problem: Problem, theta, q, controls, row, meas, mask, rmeas, rmask):
    """Scaled residuals of one frame (robust weights applied), marker predictions (mocap
    frame) and rotations at the sites."""
    pred, frames_rot, rot = _frame_markers(problem, theta, q, row)
    d = (pred - meas) / problem.noise * mask[:, None]
    # Huber weights on each marker's distance (the quadratic loss is the threshold at
    # L2_DELTA: one compiled residual serves both losses).
    e2 = jnp.sum(d * d, -1)
    big = e2 > problem.huber_delta**2
    e = jnp.sqrt(jnp.where(big, e2, 1.0))
    w = jnp.where(big, jnp.sqrt(2.0 * optax.huber_loss(e, delta=problem.huber_delta)) / e, 1.0)
    d = d * w[:, None]
    parts = [d.reshape(-1)]
    rpred = jnp.einsum("ij,mjk->mik", rot, frames_rot, precision=MATMUL_PRECISION)
    if rmeas is not None:
        rel = jnp.einsum("mji,mjk->mik", rpred, rmeas, precision=MATMUL_PRECISION)
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
        r, pred, rpred = _frame_residual(problem, th, q_, controls, row, meas, mask, rmeas, rmask)
        return (r, pred), (r, pred, rpred)

    # Along both arguments in one forward pass: one traced copy of each residual, not two.
    jac, (r, pred, rpred) = jax.jacfwd(residual, (0, 1), has_aux=True)(theta, q)
    forcing, stiffness = jax.jacfwd(equilibrium_residual, (0, 1))(theta, q)
    dq = -jnp.linalg.solve(stiffness, forcing)  # implicit function theorem

    def total(d):  # d/dtheta along the equilibrium
        d_theta, d_q = d
        return d_theta + jnp.tensordot(d_q, dq, 1, precision=MATMUL_PRECISION)

    # The markers' derivative too: a step's predicted marker motion, against which a frame's
    # actual motion tells a jump to another equilibrium branch.
    return r, total(jac[0]), pred, rpred, total(jac[1])


@jit
def _evaluate(problem, theta, q, controls, rows, meas, mask, rmeas, rmask):
    axes = (None, None, 0, 0, 0 if rows is not None else None, 0, 0)
    axes += (0 if rmeas is not None else None, 0 if rmask is not None else None)
    return jax.vmap(_frame_jacobian, in_axes=axes)(
        problem, theta, q, controls, rows, meas, mask, rmeas, rmask
    )


@jit
def _markers(problem, theta, q, rows):
    """Marker predictions of many frames at their equilibria ``q`` (no derivatives)."""
    axes = (0, 0 if rows is not None else None)
    return jax.vmap(lambda q_, row: _frame_markers(problem, theta, q_, row)[0], in_axes=axes)(
        q, rows
    )


@dataclasses.dataclass
class FrameData:
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
        rows = None if rows is None else jax.tree.map(pad, rows)
        rmeas = rmask = None
        if orient:
            ori = dataset.orientations
            ok = np.isfinite(ori.reshape(n, dataset.n_markers, 9)).all(-1)
            rmask = np.concatenate([ok.astype(float), np.zeros((total - n, ok.shape[1]))])
            rmeas = pad(np.where(ok[..., None, None], ori, np.eye(3)))
        return FrameData(n, pad(dataset.controls), rows, meas, mask, rmeas, rmask)


class Evaluator:
    """Batch equilibria (warm-started) and residual Jacobians of one dataset."""

    def __init__(self, problem, data: FrameData, chunk: int, solver_options: dict, prior=None):
        self.problem, self.data, self.chunk, self.options = problem, data, chunk, solver_options
        self.prior = prior
        self.count = 0

    def _solve(self, scene, q0, repeats: int = 1):
        """Every frame's equilibrium from ``q0`` ((frames, n) or (repeats * frames, n) rows,
        the frames repeated ``repeats`` times)."""
        d = self.data
        eq = solve_batch(
            scene,
            np.concatenate([d.controls] * repeats),
            q0=q0,
            params=self._rows(repeats),
            update=self.problem.frame_loads if d.rows is not None else None,
            chunk_size=self.chunk,
            progress=False,
            **self.options,
        )
        q = np.array(eq.q)
        return q, np.asarray(eq.converged) & np.asarray(eq.stable) & np.all(np.isfinite(q), 1)

    def _rows(self, repeats: int):
        """The frames' per-frame values (or None), the frames repeated ``repeats`` times."""
        if self.data.rows is None:
            return None
        return jax.tree.map(lambda v: np.concatenate([v] * repeats), self.data.rows)

    def __call__(self, theta, q0=None):
        """The frames' equilibria at ``theta`` from ``q0`` (default: the rest configuration),
        their residuals and Jacobians; rows that fail from ``q0`` start again from the
        straight configuration."""
        scene = self.problem.apply(jnp.asarray(theta))[0]
        q, ok = self._solve(scene, q0)
        if q0 is not None and not ok.all():
            # A warm start next to an equilibrium can stall at round-off (the energy cannot
            # decrease further); those rows start again from the straight configuration (the
            # same batch shape: no recompilation).
            q_retry, ok_retry = self._solve(scene, np.where(ok[:, None], q, 0.0))
            better = ok_retry & ~ok
            q[better], ok = q_retry[better], ok | ok_retry
        self.count += 1
        return self._evaluation(theta, q, ok)

    def from_starts(self, theta, starts: np.ndarray) -> list["Solutions"]:
        """Every frame's equilibrium at ``theta`` from each of ``starts`` ((k, n)), as one
        batch (the pool refills its slots across starts), and its markers; one
        :class:`Solutions` per start."""
        scene = self.problem.apply(jnp.asarray(theta))[0]
        frames = len(self.data.controls)
        q0 = np.repeat(np.asarray(starts, float), frames, axis=0)
        q, ok = self._solve(scene, q0, repeats=len(starts))
        self.count += 1
        d = self.data
        q_safe = jnp.asarray(np.where(ok[:, None], q, 0.0))
        pred = np.asarray(
            _markers(self.problem, jnp.asarray(theta), q_safe, self._rows(len(starts)))
        )
        out = []
        for i in range(0, len(q), frames):
            valid = ok[i : i + frames].copy()
            valid[d.n :] = False
            out.append(Solutions(q[i : i + frames], pred[i : i + frames][: d.n], valid))
        return out

    def _evaluation(self, theta, q, ok) -> "Evaluation":
        """Residuals, Jacobians and predictions of the frames at their equilibria ``q``
        (``ok``: solved)."""
        p, d = self.problem, self.data
        q_safe = np.where(ok[:, None], q, 0.0)
        rs, js, preds, rpreds, dpreds = [], [], [], [], []
        for start in range(0, len(q), self.chunk):
            sl = slice(start, start + self.chunk)
            pick = lambda x, sl=sl: None if x is None else jnp.asarray(x[sl])  # noqa: E731
            rows = (
                None
                if d.rows is None
                else jax.tree.map(lambda v, sl=sl: jnp.asarray(v[sl]), d.rows)
            )
            r, j, pred, rpred, dpred = _evaluate(
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
            dpreds.append(np.asarray(dpred))
        valid = ok.copy()
        valid[d.n :] = False
        r = np.concatenate(rs) * valid[:, None]
        j = np.concatenate(js) * valid[:, None, None]
        pred, rpred = np.concatenate(preds)[: d.n], np.concatenate(rpreds)[: d.n]
        dpred = np.concatenate(dpreds)[: d.n]
        prior = None if self.prior is None else self.prior(theta)
        return Evaluation(r, j, pred, rpred, q, valid, dpred, prior)


@dataclasses.dataclass
class Solutions:
    """The frames' equilibria from one start: no residuals or derivatives."""

    q: np.ndarray  # (rows, n) padded rows included
    pred: np.ndarray  # (frames, m, 3) marker predictions, mocap frame
    valid: np.ndarray  # (rows,) converged and stable (padded rows False)


@dataclasses.dataclass
class Evaluation:
    r: np.ndarray  # (frames, k)
    j: np.ndarray  # (frames, k, p)
    pred: np.ndarray
    rpred: np.ndarray
    q: np.ndarray
    valid: np.ndarray
    dpred: np.ndarray  # (frames, m, 3, p): d pred / d theta along the equilibria
    prior: tuple | None = None  # Prior rows (r, J) at this point

    def cost(self, valid=None) -> float:
        v = self.valid if valid is None else valid
        extra = 0.0 if self.prior is None else 0.5 * float(np.sum(self.prior[0] ** 2))
        return 0.5 * float(np.sum(self.r[v] ** 2)) + extra

    def stacked(self) -> tuple[np.ndarray, np.ndarray]:
        """Residuals (k,) and Jacobian (k, p) of the valid frames, stacked (and the priors'
        rows after them)."""
        r = self.r[self.valid].reshape(-1)
        j = self.j[self.valid].reshape(r.size, -1)
        if self.prior is None:
            return r, j
        return np.concatenate([r, self.prior[0]]), np.concatenate([j, self.prior[1]])
