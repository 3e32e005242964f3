"""The fitting problem of :func:`pacjax.identify`: parameter blocks, their bounds and priors
(the evaluation of a dataset is :mod:`pacjax._identify.evaluation`).

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

from .._config import MATMUL_PRECISION
from .._model.frameloads import FrameLoads
from .._model.robot import ExponentialStiffening
from .._model.rotation import exp_so3
from .._model.scene import Scene

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
