"""Reading scene files: the checked tables behind :func:`pacjax.io.scenefile.scene_from_toml`."""

from __future__ import annotations

import dataclasses
import difflib
import inspect
import math
import tomllib

import numpy as np

from .. import presets
from .._model.loads import Gravity, PointForce, PointMass, PointMoment
from .._model.robot import ExponentialStiffening, Robot, SectionProfile, Segment
from .._model.scene import Scene
from .._model.strain import PAC, PCC, PolynomialCurvature
from .._model.tendons import Tendon
from .._statics.options import SolverOptions

#: Presets a scene file may name, by name.
PRESETS = {"stella2023": presets.stella2023, "tentacle": presets.tentacle}
#: Base rotations (base frame -> world) of the named mounts; the robot's rest axis is the base +z.
MOUNTS = {name: np.asarray(r, float) for name, r in presets.MOUNTS.items()}

_MODELS = ("PAC", "PCC", "PolynomialCurvature")
_TOP_LEVEL = (
    "name",
    "description",
    "preset",
    "model",
    "segments",
    "robot",
    "tendons",
    "loads",
    "markers",
    "controls",
    "solver",
)
# Solver options that a file may set: every SolverOptions field that is a plain value.
SOLVER_KEYS = {
    f.name: f.default
    for f in dataclasses.fields(SolverOptions)
    if f.name != "flow_solver"  # a diffrax object: not representable in TOML
}
SOLVER_KEYS["fallback"] = True


# ------------------------------------------------------------------------------------- reading
class _Table:
    """One TOML table being read: typed getters that name the file and field on error, and a
    final check for keys nobody asked for."""

    def __init__(self, data, where: str, source: str):
        self.source = source
        self.where = where
        if not isinstance(data, dict):
            self.fail(f"must be a table, got {_describe(data)}")
        self.data = data
        self.used: set[str] = set()

    def fail(self, message: str, key: str | None = None):
        field = self.where if key is None else (f"{self.where}.{key}" if self.where else key)
        raise ValueError(f"{self.source}: {field or 'top level'}: {message}")

    def has(self, key: str) -> bool:
        """Whether ``key`` is present (it is then an allowed key of this table)."""
        self.used.add(key)
        return key in self.data

    def raw(self, key, required=False):
        """The value of ``key`` as parsed, or ``_MISSING``."""
        self.used.add(key)
        if key not in self.data:
            if required:
                typo = difflib.get_close_matches(key, [k for k in self.data if k != key], 1, 0.75)
                found = f" (found {typo[0]!r}: a typo?)" if typo else ""
                self.fail(f"missing required field{found}", key)
            return _MISSING
        return self.data[key]

    def number(self, key, default=None, required=False):
        value = self.raw(key, required)
        if value is _MISSING:
            return default
        if not _is_number(value):
            self.fail(f"expected a number, got {_describe(value)}", key)
        return float(value)

    def integer(self, key, default=None, required=False, minimum=None):
        value = self.raw(key, required)
        if value is _MISSING:
            return default
        if not isinstance(value, int) or isinstance(value, bool):
            self.fail(f"expected an integer, got {_describe(value)}", key)
        if minimum is not None and value < minimum:
            self.fail(f"must be >= {minimum}, got {value}", key)
        return value

    def boolean(self, key, default=None, required=False):
        value = self.raw(key, required)
        if value is _MISSING:
            return default
        if not isinstance(value, bool):
            self.fail(f"expected true or false, got {_describe(value)}", key)
        return value

    def string(self, key, default=None, required=False, choices=None):
        value = self.raw(key, required)
        if value is _MISSING:
            return default
        if not isinstance(value, str):
            self.fail(f"expected a string, got {_describe(value)}", key)
        if choices is not None and value not in choices:
            self.fail(f"must be one of {', '.join(map(repr, choices))}, got {value!r}", key)
        return value

    def vector(self, key, default=None, required=False, size=3):
        value = self.raw(key, required)
        if value is _MISSING:
            return default
        if not (isinstance(value, list) and len(value) == size and all(map(_is_number, value))):
            self.fail(f"expected a list of {size} numbers, got {_describe(value)}", key)
        return [float(v) for v in value]

    def numbers(self, key, default=None, required=False):
        value = self.raw(key, required)
        if value is _MISSING:
            return default
        if not (isinstance(value, list) and all(map(_is_number, value))):
            self.fail(f"expected a list of numbers, got {_describe(value)}", key)
        return [float(v) for v in value]

    def integers(self, key, size: int, minimum=None):
        value = self.raw(key)
        if value is _MISSING:
            return None
        if not (
            isinstance(value, list)
            and len(value) == size
            and all(isinstance(v, int) and not isinstance(v, bool) for v in value)
        ):
            self.fail(f"expected a list of {size} integers, got {_describe(value)}", key)
        if minimum is not None and min(value) < minimum:
            self.fail(f"must be >= {minimum} in every entry, got {value}", key)
        return tuple(value)

    def tables(self, key) -> list[_Table]:
        """An array of tables (``[[key]]``), each wrapped; empty when absent."""
        value = self.raw(key)
        if value is _MISSING:
            return []
        if not isinstance(value, list):
            self.fail(f"expected an array of tables ([[{key}]]), got {_describe(value)}", key)
        return [_Table(item, f"{key}[{i}]", self.source) for i, item in enumerate(value)]

    def table(self, key) -> _Table | None:
        value = self.raw(key)
        return None if value is _MISSING else _Table(value, key, self.source)

    def finish(self):
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            allowed = ", ".join(sorted(self.used))
            guesses = "".join(
                f"did you mean {g!r} for {k!r}?; " for k in unknown if (g := _closest(k, self.used))
            )
            allowed = f"{guesses}allowed here: {allowed}"
            hint = ""
            if self.where and set(unknown) & set(_TOP_LEVEL):
                hint = (
                    "; top-level keys such as controls or markers must come before the first "
                    "[table] of the file"
                )
            self.fail(f"unknown key(s) {', '.join(map(repr, unknown))} ({allowed}){hint}")

    def build(self, constructor, *args, **kwargs):
        """Call a pacjax constructor, re-raising its own checks with the file and table."""
        try:
            return constructor(*args, **kwargs)
        except (ValueError, TypeError) as err:
            self.fail(str(err))


_MISSING = object()
_TYPE_NAMES = {str: "string", int: "integer", float: "number", list: "array"}


def _closest(key: str, allowed) -> str | None:
    """The allowed key a typo of ``key`` most likely meant, if any is close."""
    match = difflib.get_close_matches(key, sorted(allowed), 1, 0.75)
    return match[0] if match else None


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _describe(x) -> str:
    if isinstance(x, dict):
        return "a table"
    if isinstance(x, bool):
        return f"boolean {str(x).lower()}"
    if isinstance(x, (int, float)) and not math.isfinite(x):
        return f"non-finite number {x}"
    return f"{_TYPE_NAMES.get(type(x), type(x).__name__)} {x!r}"


def scene_from_toml(text: str, source: str = "<string>", default_name: str = "scene"):
    """Like :func:`load_scene`, from the text of a scene file (``source`` names it in errors)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ValueError(f"{source}: not valid TOML: {err}") from None
    top = _Table(data, "", source)
    unknown = sorted(set(data) - set(_TOP_LEVEL))
    if unknown:
        guesses = "".join(
            f"; did you mean {g!r} for {k!r}?" for k in unknown if (g := _closest(k, _TOP_LEVEL))
        )
        top.fail(
            f"unknown table or key(s) {', '.join(map(repr, unknown))} "
            f"(allowed: {', '.join(_TOP_LEVEL)}){guesses}"
        )
    name = top.string("name", default_name)
    description = top.string("description")
    model, numerics = _read_model(top.table("model"), source)

    preset_name, preset_args = _read_preset(top)
    loads = [_read_load(t) for t in top.tables("loads")]
    if preset_name is None:
        segments, models = _read_segments(top, model)
        robot = _read_robot(top.table("robot"), segments, source)
        tendons = [_read_tendon(t, len(segments)) for t in top.tables("tendons")]
        _check_load_segments(top, loads, len(segments))
        if all(m == model for m in models):
            models = model
        scene = top.build(Scene, robot, models, tendons=tendons, loads=loads, **numerics)
    else:
        for key in ("segments", "robot", "tendons"):
            if top.has(key):
                top.fail(
                    f"[{key}] cannot be combined with preset {preset_name!r}, which defines "
                    "the robot and its tendons (set the preset's options in [preset] instead)"
                )
        kwargs = dict(preset_args, model=model)
        if "quadrature_points" in numerics:
            kwargs["quadrature_points"] = numerics.pop("quadrature_points")
        try:
            scene = PRESETS[preset_name](**kwargs)
        except (ValueError, TypeError) as err:
            raise ValueError(f"{source}: preset: {err}") from None
        _check_load_segments(top, loads, scene.n_segments)
        if loads or numerics:
            scene = _rebuild(top, scene, loads=scene.loads + tuple(loads), **numerics)

    if top.has("markers"):
        scene = _rebuild(top, scene, markers=_read_markers(top, scene.n_segments))
    controls = _read_controls(top, scene)
    solver = _read_solver(top.table("solver"))
    top.finish()
    extra = {
        "name": name,
        "description": description,
        "preset": preset_name,
        "solver": solver,
        "path": None,
    }
    return scene, controls, extra


def _rebuild(top: _Table, scene: Scene, **changes) -> Scene:
    return top.build(scene.replace, **changes)


def _read_model(t: _Table | None, source: str, family=None):
    """The model of a ``[model]`` table (or a segment's ``model``, whose unset options are
    those of ``family``, the ``[model]`` one) and its numerics."""
    if t is None:
        return PAC(), {}
    kind = t.string("type", required=True, choices=_MODELS)
    if kind == "PolynomialCurvature":
        order = t.integer("order", 3, minimum=0)
        twist = t.boolean("twist", getattr(family, "twist", False))
        model = t.build(PolynomialCurvature, order=order, twist=twist)
    else:
        frame_default = getattr(family, "frame", "torsion_free")
        frame = t.string("frame", frame_default, choices=("torsion_free", "paper"))
        phi_stiffness = t.number("phi_stiffness", getattr(family, "phi_stiffness", None))
        model = t.build(PAC if kind == "PAC" else PCC, frame=frame, phi_stiffness=phi_stiffness)
    numerics = {}
    if t.has("quadrature_points"):
        numerics["quadrature_points"] = t.integer("quadrature_points", minimum=1)
    if t.has("rotation_substeps"):
        numerics["rotation_substeps"] = t.integer("rotation_substeps", minimum=1)
    if t.has("knot_grid"):
        numerics["knot_grid"] = t.integers("knot_grid", size=2, minimum=1)
    t.finish()
    return model, numerics


def _read_preset(top: _Table):
    value = top.raw("preset")
    if value is _MISSING:
        return None, {}
    if isinstance(value, str):
        value = {"name": value}
    t = _Table(value, "preset", top.source)
    name = t.string("name", required=True, choices=tuple(PRESETS))
    signature = inspect.signature(PRESETS[name])
    args = {}
    for key, param in signature.parameters.items():
        if key in ("model", "loads") or not t.has(key):
            continue  # model and loads come from [model] and [[loads]]
        default = param.default
        if isinstance(default, bool):
            args[key] = t.boolean(key)
        elif isinstance(default, int):
            args[key] = t.integer(key)
        elif isinstance(default, float):
            args[key] = t.number(key)
        elif isinstance(default, str):
            args[key] = t.string(key)
        else:
            args[key] = t.raw(key)
    for key in ("model", "loads"):
        if key in t.data:
            t.fail(f"set the preset's {key} with [{key}] / [[{key}]], not in [preset]", key)
    t.finish()
    return name, args


def _read_segments(top: _Table, default_model) -> tuple[list[Segment], list]:
    """The segments and each one's strain model (its ``model`` key, else ``default_model``)."""
    tables = top.tables("segments")
    if not tables:
        top.fail("missing [[segments]] (or a preset): a robot needs at least one segment")
    segments, models = [], []
    for t in tables:
        repeat = t.integer("repeat", 1, minimum=1)
        model = default_model
        if t.has("model"):
            value = t.raw("model")
            if not isinstance(value, (str, dict)):
                t.fail(f"expected a model name or table, got {_describe(value)}", "model")
            model, numerics = _read_model(
                _Table(
                    {"type": value} if isinstance(value, str) else value,
                    f"{t.where}.model",
                    t.source,
                ),
                t.source,
                default_model,
            )
            if numerics:
                t.fail(
                    "quadrature_points, rotation_substeps and knot_grid belong in [model]",
                    "model",
                )
        common = dict(
            radius_tip=t.number("radius_tip"),
            inner_radius=t.number("inner_radius", 0.0),
            inner_radius_tip=t.number("inner_radius_tip"),
            stiffening=_read_stiffening(t),
            contraction_limit=t.number("contraction_limit"),
            rest_curvature=t.numbers("rest_curvature"),
            extensible=t.boolean("extensible", True),
            profile=_read_profile(t),
        )
        if t.has("young_modulus"):
            for key in (
                "bending_stiffness",
                "axial_stiffness",
                "torsion_stiffness",
                "linear_density",
            ):
                if t.has(key):
                    t.fail(
                        f"give either young_modulus (with radius, density, poisson) or "
                        f"{key}, not both",
                        key,
                    )
            segment = t.build(
                Segment.from_material,
                t.number("length", required=True),
                young_modulus=t.number("young_modulus"),
                radius=t.number("radius", required=True),
                density=t.number("density", 0.0),
                poisson=t.number("poisson", 0.5),
                **common,
            )
        else:
            for key in ("density", "poisson"):
                if t.has(key):
                    t.fail(
                        f"{key} is a material value: it needs young_modulus (else give "
                        "linear_density and torsion_stiffness)",
                        key,
                    )
            segment = t.build(
                Segment,
                length=t.number("length", required=True),
                bending_stiffness=t.number("bending_stiffness", required=True),
                axial_stiffness=t.number("axial_stiffness", required=True),
                torsion_stiffness=t.number("torsion_stiffness"),
                linear_density=t.number("linear_density", 0.0),
                radius=t.number("radius", 0.0),
                **common,
            )
        t.finish()
        segments += [segment] * repeat
        models += [model] * repeat
    return segments, models


def _read_profile(t: _Table):
    value = t.raw("profile")
    if value is _MISSING:
        return None
    if not isinstance(value, dict):
        t.fail(
            f"expected a table {{ bending = [...], density = [...] }}, got {_describe(value)}",
            "profile",
        )
    p = _Table(value, f"{t.where}.profile", t.source)
    bending = p.numbers("bending", required=True)
    density = p.numbers("density", [1.0])
    p.finish()
    return p.build(SectionProfile, bending, density)


def _read_stiffening(t: _Table):
    value = t.raw("stiffening")
    if value is _MISSING:
        return None
    law = _Table(value, f"{t.where}.stiffening", t.source)
    law.string("type", required=True, choices=("exponential",))
    rate = law.number("rate", required=True)
    law.finish()
    return law.build(ExponentialStiffening, rate)


def _read_robot(t: _Table | None, segments, source: str) -> Robot:
    if t is None:
        return Robot(segments)
    if t.has("mount") and t.has("base_rotation"):
        t.fail("give either mount or base_rotation, not both")
    rotation = None
    if t.has("mount"):
        rotation = MOUNTS[t.string("mount", choices=tuple(MOUNTS))]
    elif t.has("base_rotation"):
        rows = t.raw("base_rotation")
        if not (
            isinstance(rows, list)
            and len(rows) == 3
            and all(isinstance(r, list) and len(r) == 3 and all(map(_is_number, r)) for r in rows)
        ):
            t.fail(f"expected a 3x3 list of numbers, got {_describe(rows)}", "base_rotation")
        rotation = np.asarray(rows, float)
    position = t.vector("base_position")
    t.finish()
    return t.build(Robot, segments, base_rotation=rotation, base_position=position)


def _check_segment(t: _Table, key: str, segment: int, n_segments: int):
    if segment >= n_segments:
        t.fail(
            f"segment {segment} does not exist: the robot has {n_segments} segment(s), "
            f"indexed 0..{n_segments - 1}",
            key,
        )


def _read_tendon(t: _Table, n_segments: int) -> Tendon:
    segment = t.integer("segment", required=True, minimum=0)
    _check_segment(t, "segment", segment, n_segments)
    if t.has("angle") and t.has("angle_deg"):
        t.fail("give either angle (rad) or angle_deg, not both")
    if t.has("angle"):
        angle = t.number("angle")
    elif t.has("angle_deg"):
        angle = math.radians(t.number("angle_deg"))
    else:
        t.fail("missing required field angle_deg (or angle, rad)")
    routing = t.string("routing", "rings", choices=("rings", "channel"))
    if t.has("guides") and t.has("n_guides"):
        t.fail("give either guides or n_guides, not both")
    if routing == "channel" and (t.has("guides") or t.has("n_guides")):
        t.fail("a channel tendon has no guide rings (remove guides/n_guides)", "routing")
    if routing == "rings" and (t.has("angle_end") or t.has("angle_end_deg")):
        t.fail('angle_end applies to channel tendons only (routing = "channel")', "routing")
    guides = t.numbers("guides")
    if t.has("n_guides"):
        guides = np.linspace(0.0, 1.0, t.integer("n_guides", minimum=2)).tolist()
    if t.has("angle_end") and t.has("angle_end_deg"):
        t.fail("give either angle_end (rad) or angle_end_deg, not both")
    angle_end = t.number("angle_end")
    if t.has("angle_end_deg"):
        angle_end = math.radians(t.number("angle_end_deg"))
    mode = t.string("mode", "length", choices=("length", "tension"))
    gain = t.number("gain")
    if mode == "length" and gain is None:
        t.fail("missing required field (kappa_P, N/m) for a length-mode tendon", "gain")
    kwargs = dict(
        segment=segment,
        angle=angle,
        offset=t.number("offset", required=True),
        s=t.number("s", 1.0),
        offset_end=t.number("offset_end"),
        bowden=t.boolean("bowden", False),
        guides=guides,
        mode=mode,
        gain=gain,
        routing=routing,
        angle_end=angle_end,
    )
    t.finish()
    return t.build(Tendon, **kwargs)


_LOAD_TYPES = ("gravity", "point_mass", "point_force", "point_moment")


def _read_load(t: _Table):
    kind = t.string("type", required=True, choices=_LOAD_TYPES)
    if kind == "gravity":
        load = t.build(
            Gravity, g=t.number("g", 9.81), direction=t.vector("direction", [0.0, 0.0, -1.0])
        )
    else:
        segment = t.integer("segment", required=True, minimum=0)
        s = t.number("s", 1.0)
        if kind == "point_mass":
            load = t.build(PointMass, t.number("mass", required=True), segment, s)
        else:
            cls, key = (PointForce, "force") if kind == "point_force" else (PointMoment, "moment")
            vector = t.vector(key, required=True)
            load = t.build(cls, vector, segment, s, follower=t.boolean("follower", False))
    t.finish()
    return load


def _check_load_segments(top: _Table, loads, n_segments: int):
    for i, load in enumerate(loads):
        if not isinstance(load, Gravity):
            t = _Table(top.data["loads"][i], f"loads[{i}]", top.source)
            _check_segment(t, "segment", load.segment, n_segments)
    kinds = [type(x) for x in loads]
    if PointMass in kinds and Gravity not in kinds and not top.has("preset"):
        top.fail('a point_mass needs a [[loads]] table with type = "gravity"', "loads")


def _read_markers(top: _Table, n_segments: int):
    value = top.raw("markers")
    if not isinstance(value, list):
        top.fail(f"expected a list of [segment, s] pairs, got {_describe(value)}", "markers")
    sites = []
    for i, site in enumerate(value):
        where = f"markers[{i}]"
        ok = isinstance(site, list) and len(site) in (2, 3)
        ok = ok and isinstance(site[0], int) and not isinstance(site[0], bool)
        ok = ok and _is_number(site[1])
        if ok and len(site) == 3:
            ok = isinstance(site[2], list) and len(site[2]) == 3 and all(map(_is_number, site[2]))
        if not ok:
            top.fail(
                f"expected [segment, s] or [segment, s, [ox, oy, oz]], got {_describe(site)}",
                where,
            )
        if not 0 <= site[0] < n_segments:
            top.fail(
                f"segment {site[0]} does not exist: the robot has {n_segments} segment(s)", where
            )
        if not 0.0 <= site[1] <= 1.0:
            top.fail(f"s must lie in [0, 1], got {site[1]}", where)
        sites.append(tuple(site[:2]) + ((tuple(site[2]),) if len(site) == 3 else ()))
    return sites


def _read_controls(top: _Table, scene: Scene):
    if not top.has("controls"):
        return None
    values = top.numbers("controls")
    if len(values) != scene.n_tendons:
        top.fail(
            f"has {len(values)} value(s) but the scene has {scene.n_tendons} tendon(s)", "controls"
        )
    for i, (v, tendon) in enumerate(zip(values, scene.tendons, strict=True)):
        if tendon.mode == "tension" and v < 0:
            top.fail(f"entry {i} is a tension (N) and must be >= 0, got {v}", "controls")
    return np.asarray(values, float)


def _read_solver(t: _Table | None) -> dict:
    if t is None:
        return {}
    options = {}
    for key, default in SOLVER_KEYS.items():
        if not t.has(key):
            continue
        if isinstance(default, bool):
            options[key] = t.boolean(key)
        elif isinstance(default, int):
            options[key] = t.integer(key)
        elif isinstance(default, str):
            options[key] = t.string(key)
        else:  # floats and optional floats
            options[key] = t.number(key)
    t.finish()
    t.build(SolverOptions, **{k: v for k, v in options.items() if k != "fallback"})
    return options
