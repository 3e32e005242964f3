"""Writing scene files: :func:`pacjax.io.scenefile.scene_to_toml` and its tables."""

from __future__ import annotations

import math

import numpy as np
import tomli_w

from .._model.loads import Gravity, PointForce, PointMass, PointMoment
from .._model.robot import ExponentialStiffening, Robot, Segment
from .._model.scene import Scene
from .._model.strain import PAC, PCC, PolynomialCurvature
from .._model.tendons import DEFAULT_GUIDES, Tendon
from .scene_read import MOUNTS, SOLVER_KEYS


# ------------------------------------------------------------------------------------- writing
def _scalar(x) -> float:
    return float(np.asarray(x))


def _vector(x) -> list[float]:
    return [float(v) for v in np.asarray(x, float).reshape(-1)]


def _model_table(scene: Scene) -> dict:
    out = _model_entry(scene.model)
    if scene.quadrature_points != 8:
        out["quadrature_points"] = scene.quadrature_points
    if scene.rotation_substeps is not None:
        out["rotation_substeps"] = scene.rotation_substeps
    if scene.knot_grid is not None:
        out["knot_grid"] = list(scene.knot_grid)
    return out


def _model_entry(model) -> dict:
    out: dict = {"type": type(model).__name__}
    if isinstance(model, PolynomialCurvature):
        out["order"] = model.order
        if model.twist:
            out["twist"] = True
    elif isinstance(model, (PAC, PCC)):
        out["frame"] = model.frame
        if model.phi_stiffness is not None:
            out["phi_stiffness"] = float(model.phi_stiffness)
    else:
        raise ValueError(f"cannot write strain model {type(model).__name__} to a scene file")
    return out


def _segment_table(seg: Segment) -> dict:
    out = {
        "length": _scalar(seg.length),
        "bending_stiffness": _scalar(seg.bending_stiffness),
        "axial_stiffness": _scalar(seg.axial_stiffness),
        "torsion_stiffness": _scalar(seg.torsion_stiffness),
        "linear_density": _scalar(seg.linear_density),
        "radius": _scalar(seg.radius),
        "contraction_limit": _scalar(seg.contraction_limit),
    }
    if seg.radius_tip is not None:
        out["radius_tip"] = _scalar(seg.radius_tip)
    if _scalar(seg.inner_radius) != 0.0:
        out["inner_radius"] = _scalar(seg.inner_radius)
    if seg.inner_radius_tip is not None:
        out["inner_radius_tip"] = _scalar(seg.inner_radius_tip)
    if seg.rest_curvature is not None:
        out["rest_curvature"] = _vector(seg.rest_curvature)
    if not seg.extensible:
        out["extensible"] = False
    if seg.profile is not None:
        out["profile"] = {
            "bending": _vector(seg.profile.bending),
            "density": _vector(seg.profile.density),
        }
    if seg.stiffening is not None:
        if not isinstance(seg.stiffening, ExponentialStiffening):
            raise ValueError(
                f"cannot write stiffening law {type(seg.stiffening).__name__} to a scene file "
                "(only ExponentialStiffening has a TOML form)"
            )
        out["stiffening"] = {"type": "exponential", "rate": _scalar(seg.stiffening.rate)}
    return out


def _robot_table(robot: Robot) -> dict:
    out: dict = {}
    rotation = np.asarray(robot.base_rotation, float)
    for name, r in MOUNTS.items():
        if np.array_equal(rotation, r):
            out["mount"] = name
            break
    else:
        out["base_rotation"] = [_vector(row) for row in rotation]
    position = np.asarray(robot.base_position, float)
    if np.any(position != 0):
        out["base_position"] = _vector(position)
    return out


def _tendon_table(t: Tendon) -> dict:
    out: dict = {"segment": t.segment}
    out.update(_angle_entry("angle", _scalar(t.angle)))
    out["offset"] = _scalar(t.offset)
    if t.s != 1.0:
        out["s"] = t.s
    if t.offset_end is not None:
        out["offset_end"] = _scalar(t.offset_end)
    if t.bowden:
        out["bowden"] = True
    n = len(t.guides)
    if t.routing == "channel":
        out["routing"] = "channel"
        if t.angle_end is not None:
            out.update(_angle_entry("angle_end", _scalar(t.angle_end)))
    elif t.guides == DEFAULT_GUIDES:
        pass
    elif n >= 2 and t.guides == tuple(np.linspace(0.0, 1.0, n).tolist()):
        out["n_guides"] = n
    else:
        out["guides"] = list(t.guides)
    out["mode"] = t.mode
    if t.gain is not None:
        out["gain"] = _scalar(t.gain)
    return out


def _angle_entry(key: str, angle: float) -> dict:
    """``{key_deg: degrees}`` when that reads back to ``angle`` within a few ulps, else
    ``{key: radians}``."""
    degrees = round(math.degrees(angle), 9)
    if abs(math.radians(degrees) - angle) <= 1e-15 * max(1.0, abs(angle)):
        return {f"{key}_deg": degrees}
    return {key: angle}


def _load_table(load) -> dict:
    if isinstance(load, Gravity):
        return {"type": "gravity", "g": _scalar(load.g), "direction": _vector(load.direction)}
    if isinstance(load, PointMass):
        out = {"type": "point_mass", "mass": _scalar(load.mass)}
    elif isinstance(load, PointForce):
        out = {"type": "point_force", "force": _vector(load.force)}
    else:
        out = {"type": "point_moment", "moment": _vector(load.moment)}
    out["segment"] = load.segment
    out["s"] = _scalar(load.s)
    if isinstance(load, (PointForce, PointMoment)) and load.follower:
        out["follower"] = True
    return out


_UNITS = {
    "length": "m",
    "bending_stiffness": "EI, N m^2",
    "axial_stiffness": "N/m",
    "torsion_stiffness": "GJ, N m^2",
    "linear_density": "kg/m",
    "radius": "m",
    "radius_tip": "m",
    "inner_radius": "m",
    "inner_radius_tip": "m",
    "rest_curvature": "rad per unit s",
    "contraction_limit": "m",
    "base_position": "m",
    "offset": "m",
    "offset_end": "m",
    "gain": "kappa_P, N/m",
    "mass": "kg",
    "force": "N",
    "moment": "N m",
    "g": "m/s^2",
}


def _literal(value) -> str:
    """TOML text of a value: scalars formatted by tomli_w, arrays and tables inline."""
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_literal(v)}" for k, v in value.items()) + " }"
    if isinstance(value, list):
        return "[" + ", ".join(_literal(v) for v in value) + "]"
    return tomli_w.dumps({"v": value}).split(" = ", 1)[1].rstrip("\n")


def _key_value(key: str, value) -> str:
    text = f"{key} = {_literal(value)}"
    if isinstance(value, list) and len(text) > 100:  # one element a line
        inner = ",\n".join(f"    {_literal(v)}" for v in value)
        text = f"{key} = [\n{inner},\n]"
    unit = _UNITS.get(key)
    return f"{text}  # {unit}" if unit else text


def _table_text(header: str, table: dict) -> str:
    return "\n".join([header] + [_key_value(k, v) for k, v in table.items()])


def scene_to_toml(
    scene: Scene,
    controls=None,
    *,
    solver: dict | None = None,
    name: str | None = None,
    description: str | None = None,
) -> str:
    """The scene file text of ``scene`` (explicit form: segments, robot, tendons, loads).

    Identical consecutive segments are written once with ``repeat``. ``load_scene`` of the
    result rebuilds the same scene: parameters are written exactly, except tendon angles, which
    are written in degrees when that reads back to within a few ulps (else in radians).

    Args:
        scene: the :class:`Scene`.
        controls: optional controls (one per tendon) to store with it.
        solver: optional keyword arguments for :func:`pacjax.solve_equilibrium`.
        name: optional scene name.
        description: optional description.
    """
    top: dict = {}
    if name is not None:
        top["name"] = name
    if description is not None:
        top["description"] = description
    if controls is not None:
        values = _vector(controls)
        if len(values) != scene.n_tendons:
            raise ValueError(
                f"controls has {len(values)} value(s) but the scene has {scene.n_tendons} tendons"
            )
        top["controls"] = values
    if scene.markers:
        top["markers"] = [
            [seg, s] if not any(offset) else [seg, s, list(offset)]
            for seg, s, offset in scene.markers
        ]
    segments: list[dict] = []
    for seg, model in zip(scene.robot.segments, scene.models, strict=True):
        table = _segment_table(seg)
        if scene.segment_models is not None and model != scene.model:
            table["model"] = _model_entry(model)
        if segments and {k: v for k, v in segments[-1].items() if k != "repeat"} == table:
            segments[-1]["repeat"] = segments[-1].get("repeat", 1) + 1
        else:
            segments.append(table)
    chunks = ["# pacjax scene file (SI units; see pacjax.io.scenefile)"]
    if top:
        chunks.append("\n".join(_key_value(k, v) for k, v in top.items()))
    chunks.append(_table_text("[model]", _model_table(scene)))
    chunks += [_table_text("[[segments]]", t) for t in segments]
    robot = _robot_table(scene.robot)
    if robot:
        chunks.append(_table_text("[robot]", robot))
    chunks += [_table_text("[[tendons]]", _tendon_table(t)) for t in scene.tendons]
    chunks += [_table_text("[[loads]]", _load_table(x)) for x in scene.loads]
    if solver:
        unknown = set(solver) - set(SOLVER_KEYS)
        if unknown:
            raise ValueError(f"solver options {sorted(unknown)} cannot be written to a file")
        chunks.append(_table_text("[solver]", dict(solver)))
    return "\n\n".join(chunks) + "\n"
