"""The fitting problem of :func:`pacjax.identify`: parameter blocks, residuals and their
implicit-function-theorem Jacobians, and the warm-started batch evaluation of a dataset.

A :class:`Problem` holds the scene (with the dataset's per-frame loads), the fitted parameter
blocks and their starting values; ``Problem.apply(theta)`` puts internal coordinates into the
scene. Positive parameters are ``start * exp(theta)`` (positivity by reparametrisation), the
others ``start + scale * theta``. Equal structure means no recompilation across fits.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from .._config import MATMUL_PRECISION
from .._jit import jit
from .._model.frameloads import FrameLoads
from .._model.robot import ExponentialStiffening
from .._model.rotation import exp_so3, matvec3
from .._model.scene import Scene
from .._statics.batch import solve_batch
from .dataset import MocapDataset

PARAMETERS = {
    "bending_stiffness": ("segment", "N m^2", True),
    "axial_stiffness": ("segment", "N/m", True),
    "torsion_stiffness": ("segment", "N m^2", True),
    "linear_density": ("segment", "kg/m", True),
    "stiffening": ("segment", "1", False),
    # Material values of a circular section (Segment.radius, inner_radius): E scales EI, GJ and
    # the axial stiffness together, rho the linear density.
    "young_modulus": ("segment", "Pa", True),
    "density": ("segment", "kg/m^3", True),
    "rest_curvature": ("rest", "rad", False),
    "tendon_gain": ("tendon", "N/m", True),
    "tendon_offset": ("tendon", "m", True),
    "mocap_transform": ("transform", "rad | m", False),
    "marker_offsets": ("marker", "m", False),
}
#: Default physical bounds (lower, upper) of each parameter: absolute numbers, or ``("x", a,
#: b)`` for ``a`` and ``b`` times the starting value. Positive parameters are fitted in log
#: space within them; ``identify(bounds=...)`` overrides any of them.
DEFAULT_BOUNDS = {
    "bending_stiffness": ("x", 1e-3, 1e3),
    "axial_stiffness": ("x", 1e-3, 1e3),
    "torsion_stiffness": ("x", 1e-3, 1e3),
    "linear_density": ("x", 1e-3, 1e3),
    "stiffening": (-50.0, 50.0),
    "young_modulus": (1e2, 1e12),  # Pa: softer than any gel to stiffer than steel
    "density": (1.0, 3.0e4),  # kg/m^3: foams to tungsten
    "rest_curvature": (-4.0 * np.pi, 4.0 * np.pi),  # rad per unit s: two turns a segment
    "tendon_gain": ("x", 1e-3, 1e3),
    "tendon_offset": ("x", 0.1, 10.0),
    "mocap_transform": (-np.inf, np.inf),
    "marker_offsets": (-0.2, 0.2),  # m from the starting offsets
}
#: Huber threshold that makes the loss quadratic (squares stay finite in float64).
L2_DELTA = 1e150
STEP_SCALE = {"stiffening": 1.0, "mocap_transform": 1.0, "marker_offsets": 0.01}


class Block(eqx.Module):
    """One fitted parameter group (static description)."""

    name: str = eqx.field(static=True)
    size: int = eqx.field(static=True)  # internal coordinates
    targets: tuple = eqx.field(static=True)  # segment / tendon / marker indices written
    log: bool = eqx.field(static=True)


class Problem(eqx.Module):
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

    @property
    def n_theta(self) -> int:
        return sum(b.size for b in self.blocks)

    def split(self, theta):
        out, k = [], 0
        for b in self.blocks:
            out.append(theta[k : k + b.size])
            k += b.size
        return out

    def physical(self, block: Block, init, th):
        if block.name == "mocap_transform":
            return th
        if block.name == "marker_offsets":
            return init + STEP_SCALE["marker_offsets"] * th.reshape(init.shape)
        if block.log:
            return init * jnp.exp(th)  # th broadcasts when shared
        return init + STEP_SCALE.get(block.name, 1.0) * th

    def apply(self, theta):
        """``(scene, rotation, translation, offsets)`` at internal coordinates ``theta``."""
        scene, rot, trans, offsets = self.scene, self.rotation0, self.translation0, self.offsets
        for block, init, th in zip(self.blocks, self.initial, self.split(theta), strict=True):
            value = self.physical(block, init, th)
            if block.name == "mocap_transform":
                rot = jnp.matmul(exp_so3(value[:3]), self.rotation0, precision=MATMUL_PRECISION)
                trans = self.translation0 + value[3:]
            elif block.name == "marker_offsets":
                offsets = value
            else:
                scene = _put(scene, block, value)
        return scene, rot, trans, offsets


def _put(scene: Scene, block: Block, value) -> Scene:
    idx = block.targets
    name = block.name
    if name in ("young_modulus", "density"):
        return _put_material(scene, name, idx, value)
    if name == "rest_curvature":
        sizes = [scene.robot.segments[i].rest_curvature.shape[0] for i in idx]
        parts = jnp.split(value, np.cumsum(sizes)[:-1])
        return eqx.tree_at(
            lambda s: [s.robot.segments[i].rest_curvature for i in idx], scene, list(parts)
        )
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


def _put_material(scene: Scene, name: str, idx, value) -> Scene:
    """Young's modulus: EI = E I, and GJ and the axial stiffness in proportion (Poisson's ratio
    and the section kept); density: rho A = rho A."""
    segments = list(scene.robot.segments)
    for k, i in enumerate(idx):
        seg = segments[i]
        second_moment, area = seg.base_section()
        if name == "density":
            segments[i] = eqx.tree_at(lambda x: x.linear_density, seg, value[k] * area)
            continue
        ratio = value[k] * second_moment / seg.bending_stiffness
        segments[i] = eqx.tree_at(
            lambda x: (x.bending_stiffness, x.torsion_stiffness, x.axial_stiffness),
            seg,
            (value[k] * second_moment, seg.torsion_stiffness * ratio, seg.axial_stiffness * ratio),
        )
    return eqx.tree_at(lambda s: s.robot.segments, scene, tuple(segments))


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


# ------------------------------------------------------------------------------ set-up
def make_blocks(scene: Scene, params, per_segment, n_markers) -> tuple[Scene, list, list, list]:
    """Blocks, starting values and labels; adds zero stiffening laws where they are fitted."""
    params = check_params(params, per_segment)
    if "stiffening" in params:
        scene = _with_stiffening_laws(scene)
    if "rest_curvature" in params:
        scene = _with_rest_curvature(scene)
    blocks, initial, labels = [], [], []
    for name in params:
        block, values, label = _block(scene, name, name in per_segment, n_markers)
        blocks.append(block)
        initial.append(None if values is None else np.asarray(values, float))
        labels.append(label)
    return scene, blocks, initial, labels


def check_params(params, per_segment) -> tuple:
    """``params`` as a tuple of known, distinct names; ``per_segment`` a subset of them that
    are segment or tendon parameters."""
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
    for material, fields in _MATERIAL_FIELDS.items():
        both = [f for f in fields if material in params and f in params]
        if both:
            raise ValueError(
                f"params: {material} sets {', '.join(fields)}; fit it or {both[0]}, not both"
            )
    for name in per_segment:
        if name not in params:
            raise ValueError(f"per_segment names {name!r}, which is not in params")
        if PARAMETERS[name][0] not in ("segment", "tendon"):
            raise ValueError(f"per_segment applies to segment and tendon parameters, not {name!r}")
    return params


_MATERIAL_FIELDS = {
    "young_modulus": ("bending_stiffness", "torsion_stiffness", "axial_stiffness"),
    "density": ("linear_density",),
}


def _with_rest_curvature(scene: Scene) -> Scene:
    """``scene`` with a zero rest curvature on every segment without one."""
    segments = tuple(
        seg
        if seg.rest_curvature is not None
        else dataclasses.replace(seg, rest_curvature=np.zeros(model.dofs_per_segment() - 1))
        for seg, model in zip(scene.robot.segments, scene.models, strict=True)
    )
    return eqx.tree_at(lambda s: s.robot.segments, scene, segments)


def _with_stiffening_laws(scene: Scene) -> Scene:
    """``scene`` with a zero-rate exponential stiffening law on every segment without one."""
    segments = [
        seg
        if seg.stiffening is not None
        else dataclasses.replace(seg, stiffening=ExponentialStiffening(0.0))
        for seg in scene.robot.segments
    ]
    if not all(isinstance(seg.stiffening, ExponentialStiffening) for seg in segments):
        raise ValueError("stiffening can be fitted for ExponentialStiffening laws only")
    return eqx.tree_at(lambda s: s.robot.segments, scene, tuple(segments))


def _block(scene: Scene, name: str, per: bool, n_markers: int) -> tuple[Block, list | None, list]:
    """The block of parameter ``name`` (one value per segment / tendon with ``per``), its
    starting values (None for marker offsets) and the labels of its reported values."""
    kind, unit, positive = PARAMETERS[name]
    idx, values, label = _targets(scene, name, kind, n_markers)
    if positive and any(v <= 0 for v in values):
        raise ValueError(
            f"{name}: the starting value must be > 0 to fit it (log scale), got {values}"
        )
    if kind in ("segment", "tendon"):
        size = len(idx) if per else 1
    elif kind == "rest":
        size = len(values)
    elif kind == "transform":
        size = 6
    else:
        size = 3 * n_markers
    if not per and kind in ("segment", "tendon") and len(set(values)) == 1:
        label = [""]  # one shared factor on equal values: reported as one value
    return Block(name, size, idx, positive), values, label


def _targets(scene: Scene, name: str, kind: str, n_markers: int) -> tuple[tuple, list | None, list]:
    """The segments / tendons / markers parameter ``name`` writes, their starting values and
    labels."""
    if kind == "segment":
        idx = tuple(range(scene.n_segments))
        if name == "stiffening":
            values = [float(seg.stiffening.rate) for seg in scene.robot.segments]
        elif name in ("young_modulus", "density"):
            values = [_material_value(seg, name, i) for i, seg in enumerate(scene.robot.segments)]
        else:
            values = [float(getattr(seg, name)) for seg in scene.robot.segments]
        return idx, values, [f"[{i}]" for i in idx]
    if kind == "tendon":
        idx = tuple(
            i for i, t in enumerate(scene.tendons) if name != "tendon_gain" or t.mode == "length"
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
        return idx, values, [f"[{i}]" for i in idx]
    if kind == "rest":
        idx = tuple(range(scene.n_segments))
        values, labels = [], []
        for i, (seg, model) in enumerate(zip(scene.robot.segments, scene.models, strict=True)):
            values += [float(v) for v in np.asarray(seg.rest_curvature)]
            labels += [f"[{i}].{c}" for c in model.coordinate_names()[:-1]]
        return idx, values, labels
    if kind == "transform":
        return (), [0.0] * 6, ["[rx]", "[ry]", "[rz]", "[tx]", "[ty]", "[tz]"]
    idx = tuple(range(n_markers))
    return idx, None, [f"[{j}].{a}" for j in range(n_markers) for a in "xyz"]


def _material_value(segment, name: str, i: int) -> float:
    """A segment's Young's modulus (Pa) or density (kg/m^3), from its section."""
    if not float(segment.radius) > float(segment.inner_radius):
        raise ValueError(
            f"{name}: segment {i} has no section (Segment.radius = {float(segment.radius)} m); "
            "build it with Segment.from_material or give its radius"
        )
    second_moment, area = segment.base_section()
    if name == "density":
        return float(segment.linear_density / area)
    return float(segment.bending_stiffness / second_moment)


def theta_bounds(blocks, initial, bounds: dict | None) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of the internal coordinates from the physical ones (the
    defaults of :data:`DEFAULT_BOUNDS`, overridden by ``bounds``: name -> (lower, upper), None
    for a default side). Raises a ValueError naming the parameter when a bound is malformed or
    the starting value lies outside it."""
    bounds = {} if bounds is None else dict(bounds)
    unknown = sorted(set(bounds) - {b.name for b in blocks})
    if unknown:
        raise ValueError(f"bounds names {unknown}, which are not fitted")
    lower, upper = [], []
    for block, init in zip(blocks, initial, strict=True):
        lo, hi = _physical_bounds(block, init, bounds.get(block.name))
        if block.name == "mocap_transform":
            lower.append(np.full(block.size, -np.inf))
            upper.append(np.full(block.size, np.inf))
            continue
        start = np.zeros(block.size) if init is None else np.asarray(init, float).reshape(-1)
        if init is None or block.name == "marker_offsets":
            scale = STEP_SCALE.get(block.name, 1.0)
            lower.append(np.full(block.size, lo / scale))  # offsets: bounds on the change
            upper.append(np.full(block.size, hi / scale))
            continue
        if np.any(start < lo) or np.any(start > hi):
            raise ValueError(
                f"bounds: {block.name} starts at {start.tolist()}, outside its bounds "
                f"[{lo:g}, {hi:g}]"
            )
        if block.log:
            with np.errstate(divide="ignore"):
                th_lo, th_hi = np.log(lo / start), np.log(hi / start)
        else:
            scale = STEP_SCALE.get(block.name, 1.0)
            th_lo, th_hi = (lo - start) / scale, (hi - start) / scale
        if block.size != start.size:  # one shared factor: the tightest of its values
            th_lo, th_hi = np.full(block.size, th_lo.max()), np.full(block.size, th_hi.min())
        lower.append(th_lo)
        upper.append(th_hi)
    return np.concatenate(lower), np.concatenate(upper)


def _physical_bounds(block, init, given) -> tuple[float, float]:
    default = DEFAULT_BOUNDS[block.name]
    if default[0] == "x":
        start = np.asarray(init, float)
        lo, hi = default[1] * start.min(), default[2] * start.max()
    else:
        lo, hi = default
    if given is not None:
        if not (isinstance(given, (tuple, list)) and len(given) == 2):
            raise ValueError(f"bounds[{block.name!r}] must be (lower, upper), got {given!r}")
        lo = lo if given[0] is None else float(given[0])
        hi = hi if given[1] is None else float(given[1])
    if not lo < hi or (block.log and not lo > 0):
        raise ValueError(
            f"bounds[{block.name!r}] must have lower < upper"
            + (" and lower > 0 (a positive parameter)" if block.log else "")
            + f", got ({lo:g}, {hi:g})"
        )
    return lo, hi


def kabsch(world: np.ndarray, measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation and translation with ``measured ~ R world + t`` (observed points only)."""
    ok = np.isfinite(measured).all(-1)
    a, b = world[ok], measured[ok]
    ca, cb = a.mean(0), b.mean(0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, cb - r @ ca


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
        tile = lambda x: None if x is None else np.concatenate([x] * repeats)  # noqa: E731
        eq = solve_batch(
            scene,
            tile(d.controls),
            q0=q0,
            params=None if d.rows is None else jax.tree.map(tile, d.rows),
            update=self.problem.frame_loads if d.rows is not None else None,
            chunk_size=self.chunk,
            progress=False,
            **self.options,
        )
        q = np.array(eq.q)
        return q, np.asarray(eq.converged) & np.asarray(eq.stable) & np.all(np.isfinite(q), 1)

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
        rows = (
            None
            if d.rows is None
            else jax.tree.map(lambda v: np.concatenate([v] * len(starts)), d.rows)
        )
        pred = np.asarray(
            _markers(
                self.problem, jnp.asarray(theta), jnp.asarray(np.where(ok[:, None], q, 0.0)), rows
            )
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


class Prior:
    """Gaussian priors on fitted parameters as extra residual rows ``(value - mean) / std``
    (physical units) with their Jacobian along the internal coordinates."""

    def __init__(self, problem: Problem, priors: dict):
        names = {b.name for b in problem.blocks}
        unknown = sorted(set(priors) - names)
        if unknown:
            raise ValueError(f"priors names {unknown}, which are not fitted")
        self.terms = []
        for name, value in priors.items():
            if not (isinstance(value, (tuple, list)) and len(value) == 2):
                raise ValueError(f"priors[{name!r}] must be (mean, std), got {value!r}")
            mean, std = (np.asarray(v, float) for v in value)
            if not (np.all(np.isfinite(mean)) and np.all(std > 0)):
                raise ValueError(f"priors[{name!r}]: mean must be finite and std > 0")
            self.terms.append((name, jnp.asarray(mean), jnp.asarray(std)))
        self.problem = problem
        self._rows = jax.jit(jax.jacfwd(self.rows, has_aux=True))

    def rows(self, theta):
        p = self.problem
        out = []
        for block, init, th in zip(p.blocks, p.initial, p.split(theta), strict=True):
            for name, mean, std in self.terms:
                if name == block.name:
                    value = jnp.ravel(p.physical(block, init, th))
                    out.append(jnp.ravel((value - mean) / std))
        r = jnp.concatenate(out)
        return r, r

    def __call__(self, theta) -> tuple[np.ndarray, np.ndarray]:
        jac, r = self._rows(jnp.asarray(theta))
        return np.asarray(r), np.asarray(jac)


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
