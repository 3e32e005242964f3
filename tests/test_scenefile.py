"""Scene files: round trips, the example scenes, and clear errors for malformed files."""

import math
import pathlib
import re
import textwrap

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pacjax as pj
from pacjax.io import scenefile
from pacjax.io.scenefile import load_scene, save_scene, scene_from_toml, scene_to_toml

SCENES = pathlib.Path(__file__).resolve().parent.parent / "experiments" / "scenes"
EXAMPLES = sorted(SCENES.glob("*.toml"))
tip_pose = eqx.filter_jit(pj.tip_pose)  # op by op, the kinematics take seconds


def assert_same_scene(a: pj.Scene, b: pj.Scene, rtol=0.0, atol=1e-15):
    """Same structure (so the same compiled solver) and the same parameters."""
    leaves_a, tree_a = jax.tree_util.tree_flatten(a)
    leaves_b, tree_b = jax.tree_util.tree_flatten(b)
    assert tree_a == tree_b
    for x, y in zip(leaves_a, leaves_b, strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=rtol, atol=atol)


def full_scene() -> pj.Scene:
    """A scene using every feature the file format has."""
    tapered = pj.Segment(
        0.12,
        0.03,
        900.0,
        torsion_stiffness=0.025,
        linear_density=0.4,
        radius=0.02,
        radius_tip=0.015,
        stiffening=pj.ExponentialStiffening(1.5),
    )
    plain = pj.Segment(0.1, 0.02, 800.0, linear_density=0.3, radius=0.015)
    c, s = math.cos(0.3), math.sin(0.3)
    robot = pj.Robot(
        [tapered, plain, plain],
        base_rotation=np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]),
        base_position=(0.0, 0.01, 0.2),
    )
    tendons = [
        pj.Tendon(0, 0.1234, 0.018, s=0.7, offset_end=0.012, guides=(0.0, 0.3, 0.6), gain=5e3),
        pj.Tendon(1, math.pi, 0.012, bowden=True, mode="tension"),
        pj.Tendon(2, -math.pi / 2, 0.012, guides=np.linspace(0, 1, 7).tolist(), gain=1e4),
    ]
    loads = [
        pj.Gravity(9.81, (0.0, -1.0, 0.0)),
        pj.PointMass(0.05, 2, 1.0),
        pj.PointForce((0.1, 0.0, 0.0), 1, 0.5),
        pj.PointForce((0.0, 0.2, 0.0), 2, 1.0, follower=True),
        pj.PointMoment((0.0, 0.0, 0.01), 2, 0.9, follower=True),
    ]
    return pj.Scene(
        robot,
        pj.PolynomialCurvature(order=2, twist=True),
        tendons=tendons,
        loads=loads,
        markers=[(0, 0.5), (2, 1.0, (0.0, 0.01, 0.0))],
        quadrature_points=6,
        rotation_substeps=3,
        knot_grid=(6, 3),
    )


# ------------------------------------------------------------------------------ round trips
def test_round_trip_every_feature(tmp_path):
    scene = full_scene()
    controls = np.array([0.01, 1.5, 0.0])
    solver = {"tol": 1e-9, "max_steps": 50, "method": "ptc", "fallback": False}
    path = tmp_path / "full.toml"
    save_scene(path, scene, controls, solver=solver, name="everything")
    back, back_controls, extra = load_scene(path)
    assert_same_scene(scene, back)
    np.testing.assert_array_equal(back_controls, controls)
    assert extra == {
        "name": "everything",
        "description": None,
        "preset": None,
        "solver": solver,
        "path": str(path),
    }
    # Writing again gives the same text: the format is a fixed point.
    assert scene_to_toml(back, back_controls, solver=solver, name="everything") == (
        path.read_text()
    )


@pytest.mark.parametrize("model", [pj.PCC(), pj.PAC(frame="paper", phi_stiffness=0.5)])
def test_round_trip_planar_models(model):
    scene = pj.presets.stella2023(model, mount="horizontal", n_sections=2)
    back, controls, _ = scene_from_toml(scene_to_toml(scene))
    assert controls is None
    assert_same_scene(scene, back)


def test_round_trip_same_equilibrium():
    scene, controls, _ = load_scene(SCENES / "tendon_single.toml")
    back, back_controls, _ = scene_from_toml(scene_to_toml(scene, controls))
    a = pj.solve_equilibrium(scene, controls)
    b = pj.solve_equilibrium(back, back_controls)
    assert bool(a.converged) and bool(b.converged)
    np.testing.assert_allclose(np.asarray(b.q), np.asarray(a.q), rtol=0, atol=1e-12)


def test_written_file_is_readable():
    text = scene_to_toml(pj.presets.stella2023(tip_mass=0.2), np.zeros(9))
    assert 'mount = "hanging"' in text
    assert "repeat = 3" in text
    assert 'stiffening = { type = "exponential"' in text
    assert "angle_deg = 210.0" in text
    assert max(len(line) for line in text.splitlines()) <= 100


def test_preset_matches_python():
    scene, controls, extra = load_scene(SCENES / "stella2023.toml")
    assert extra["preset"] == "stella2023"
    assert controls.shape == (9,)
    assert_same_scene(scene, pj.presets.stella2023(pj.PAC(), tip_mass=0.2))


def test_preset_string_form_and_extra_loads():
    text = """
        preset = "stella2023"
        [[loads]]
        type = "point_force"
        force = [0.5, 0, 0]
        segment = 2
    """
    scene, _, extra = scene_from_toml(text)
    expected = pj.presets.stella2023(loads=(pj.PointForce((0.5, 0.0, 0.0), 2, 1.0),))
    assert_same_scene(scene, expected)
    assert extra["name"] == "scene"


def test_documented_examples_parse():
    blocks = re.findall(r"::\n\n((?:    .*\n|\n)+)", scenefile.__doc__)
    assert len(blocks) == 2
    full, preset = (scene_from_toml(textwrap.dedent(b), source="docstring") for b in blocks)
    scene, controls, extra = full
    assert (scene.n_segments, scene.n_tendons, len(scene.loads)) == (3, 1, 4)
    assert scene.segment_models[2] == pj.PCC(phi_stiffness=1e-3)
    assert not scene.robot.segments[2].extensible and scene.n_dofs == 2 * 4 + 2
    assert controls.shape == (1,) and extra["solver"] == {"tol": 1e-10, "max_steps": 100}
    assert preset[0].n_tendons == 9 and preset[2]["preset"] == "stella2023"


# ------------------------------------------------------------------------------ examples
@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
@pytest.mark.slow  # over a minute of compilation: CI's slow step
def test_example_loads_and_solves(path):
    scene, controls, extra = load_scene(path)
    eq = pj.solve_equilibrium(scene, controls, **extra["solver"])
    assert bool(eq.converged), (path.name, eq.reason)
    assert bool(eq.stable)
    tip, _ = tip_pose(scene, eq.q)
    tip = np.asarray(tip)
    if path.stem == "cantilever":
        # Horizontal along +x, pulled down: less than the linear estimate (64 mm), more than
        # the tip load alone would give in the elastica regime's lower bound.
        assert 0.28 < tip[0] < 0.3 and -0.064 < tip[2] < -0.045
    elif path.stem == "tendon_single":
        assert tip[1] > 0.005  # the 3 N tendon at +y bends the tip towards +y
    elif path.stem == "follower":
        assert tip[0] > 0.01  # pushed along the tip's local +x
    elif path.stem == "stella2023":
        assert tip[2] < -0.3  # hanging down
    elif path.stem == "tentacle_channels":
        # The same robot as the preset; tendon 0 pulls the tip towards world +y.
        same = pj.solve_equilibrium(pj.presets.tentacle(), controls)
        np.testing.assert_allclose(eq.q, same.q, atol=1e-5)
        assert tip[1] > 0.01


def test_examples_exist():
    assert {p.stem for p in EXAMPLES} >= {
        "stella2023",
        "cantilever",
        "tendon_single",
        "follower",
        "tentacle_channels",
    }


# ------------------------------------------------------------------------------ errors
BASE = """
[[segments]]
length = 0.1
bending_stiffness = 0.02
axial_stiffness = 800.0
radius = 0.01
"""
TENDON = """
[[tendons]]
segment = 0
angle_deg = 90
offset = 0.008
gain = 1e4
"""

MALFORMED = {
    "bad TOML": ("[[segments]\nlength = 0.1", ["not valid TOML"]),
    "unknown top-level": (BASE + "\n[segmnets]\nx = 1", ["'segmnets'", "allowed"]),
    "unknown key": (BASE + "lenght = 0.2\n", ["segments[0]", "'lenght'", "unknown"]),
    "missing field": (
        "[[segments]]\nlength = 0.1\naxial_stiffness = 1.0\n",
        ["segments[0].bending_stiffness", "missing required field"],
    ),
    "wrong type": (
        BASE.replace("0.02", '"stiff"'),
        ["segments[0].bending_stiffness", "expected a number", "'stiff'"],
    ),
    "negative stiffness": (
        BASE.replace("800.0", "-800.0"),
        ["segments[0]", "axial_stiffness", "> 0"],
    ),
    "no segments": ('[model]\ntype = "PCC"\n', ["[[segments]]", "missing"]),
    "bad model": (BASE + '[model]\ntype = "PCCC"\n', ["model.type", "'PCCC'", "one of"]),
    "bad order": (
        BASE + '[model]\ntype = "PolynomialCurvature"\norder = 1.5\n',
        ["model.order", "expected an integer"],
    ),
    "tendon on missing segment": (
        BASE + TENDON.replace("segment = 0", "segment = 2"),
        ["tendons[0].segment", "segment 2 does not exist", "1 segment"],
    ),
    "tendon without angle": (
        BASE + TENDON.replace("angle_deg = 90", ""),
        ["tendons[0]", "angle_deg"],
    ),
    "tendon both angles": (
        BASE + TENDON.replace("angle_deg = 90", "angle_deg = 90\nangle = 1.0"),
        ["tendons[0]", "not both"],
    ),
    "length tendon without gain": (
        BASE + TENDON.replace("gain = 1e4", ""),
        ["tendons[0].gain", "missing required field", "length-mode"],
    ),
    "bad tendon mode": (
        BASE + TENDON + 'mode = "force"\n',
        ["tendons[0].mode", "'force'", "'length', 'tension'"],
    ),
    "bad guides": (
        BASE + TENDON + "guides = [0.0, 1.5]\n",
        ["tendons[0]", "guides"],
    ),
    "load on missing segment": (
        BASE + '[[loads]]\ntype = "point_force"\nforce = [1, 0, 0]\nsegment = 4\n',
        ["loads[0].segment", "segment 4 does not exist"],
    ),
    "bad load type": (BASE + '[[loads]]\ntype = "spring"\n', ["loads[0].type", "'spring'"]),
    "bad force vector": (
        BASE + '[[loads]]\ntype = "point_force"\nforce = [1, 0]\nsegment = 0\n',
        ["loads[0].force", "list of 3 numbers"],
    ),
    "mass without gravity": (
        BASE + '[[loads]]\ntype = "point_mass"\nmass = 0.1\nsegment = 0\n',
        ["loads", "gravity"],
    ),
    "controls count": (
        "controls = [0.01, 0.02]\n" + BASE + TENDON,
        ["controls", "2 value(s)", "1 tendon(s)"],
    ),
    "negative tension": (
        "controls = [-1.0]\n" + BASE + TENDON.replace("gain = 1e4", 'mode = "tension"'),
        ["controls", "tension", ">= 0"],
    ),
    "bad mount": (BASE + '[robot]\nmount = "sideways"\n', ["robot.mount", "'sideways'"]),
    "mount and rotation": (
        BASE + '[robot]\nmount = "upright"\nbase_rotation = [[1,0,0],[0,1,0],[0,0,1]]\n',
        ["robot", "not both"],
    ),
    "improper rotation": (
        BASE + "[robot]\nbase_rotation = [[1,0,0],[0,1,0],[0,0,-1]]\n",
        ["robot", "rotation"],
    ),
    "bad marker": ("markers = [[0, 1.5]]\n" + BASE, ["markers[0]", "[0, 1]"]),
    "marker on missing segment": ("markers = [[3, 0.5]]\n" + BASE, ["markers[0]", "segment 3"]),
    "top-level key after a table": (
        BASE + TENDON + "controls = [0.01]\n",
        ["tendons[0]", "'controls'", "before the first [table]"],
    ),
    "unknown solver option": (BASE + "[solver]\ntolerance = 1e-9\n", ["solver", "'tolerance'"]),
    "bad solver value": (BASE + '[solver]\nmethod = "rk4"\n', ["solver", "method"]),
    "unknown preset": ('preset = "stella2024"\n', ["preset.name", "'stella2024'"]),
    "preset with segments": (
        BASE + '[preset]\nname = "stella2023"\n',
        ["[segments]", "cannot be combined", "stella2023"],
    ),
    "bad preset option": (
        '[preset]\nname = "stella2023"\ntip_mass = "heavy"\n',
        ["preset.tip_mass", "expected a number"],
    ),
    "unknown preset option": (
        '[preset]\nname = "stella2023"\npayload = 0.2\n',
        ["preset", "'payload'"],
    ),
    "bad stiffening": (
        BASE + 'stiffening = { type = "linear", rate = 1 }\n',
        ["segments[0].stiffening.type", "'linear'"],
    ),
    "zero repeat": (BASE + "repeat = 0\n", ["segments[0].repeat", ">= 1"]),
    # issue 6: non-finite numbers, zero sizes, ranges, types and names
    "nan length": (BASE.replace("0.1", "nan"), ["segments[0].length", "non-finite"]),
    "inf stiffness": (BASE.replace("0.02", "inf"), ["segments[0].bending_stiffness", "non-finite"]),
    "zero length": (BASE.replace("0.1", "0.0"), ["segments[0]", "Segment.length", "> 0"]),
    "zero bending stiffness": (
        BASE.replace("0.02", "0"),
        ["segments[0]", "Segment.bending_stiffness", "> 0"],
    ),
    "nan guide": (BASE + TENDON + "guides = [0.0, nan]\n", ["tendons[0].guides", "numbers"]),
    "guide below zero": (BASE + TENDON + "guides = [-0.5, 1.0]\n", ["tendons[0]", "[0, 1]"]),
    "anchor outside": (BASE + TENDON + "s = 1.5\n", ["tendons[0]", "Tendon.s", "(0, 1]"]),
    "inf payload": (
        BASE + '[[loads]]\ntype = "gravity"\n[[loads]]\ntype = "point_mass"\nmass = inf\n'
        "segment = 0\n",
        ["loads[1].mass", "non-finite"],
    ),
    "nan control": ("controls = [nan]\n" + BASE + TENDON, ["controls", "list of numbers"]),
    "nan tension-mode gain": (
        BASE + TENDON.replace("gain = 1e4", 'mode = "tension"\ngain = nan'),
        ["tendons[0].gain", "non-finite"],
    ),
    "model name not a string": (BASE + "[model]\ntype = 3\n", ["model.type", "expected a string"]),
    "model as a string": ('model = "PAC"\n' + BASE, ["model", "must be a table"]),
    "model without type": (BASE + "[model]\nframe = 'paper'\n", ["model.type", "missing"]),
    "key of another model": (
        BASE + "[model]\ntype = 'PAC'\norder = 2\n",
        ["model", "unknown key(s) 'order'"],
    ),
    "segments not tables": ("segments = 1\n", ["segments", "array of tables"]),
    "knot grid of one number": (
        BASE + "[model]\ntype = 'PAC'\nknot_grid = 4\n",
        ["model.knot_grid", "expected a list of 2 integers"],
    ),
    "knot grid of no nodes": (
        BASE + "[model]\ntype = 'PAC'\nknot_grid = [4, 0]\n",
        ["model.knot_grid", "must be >= 1"],
    ),
    "string follower": (
        BASE + '[[loads]]\ntype = "point_force"\nforce = [1, 0, 0]\nsegment = 0\n'
        'follower = "yes"\n',
        ["loads[0].follower", "true or false"],
    ),
    "empty file": ("", ["missing [[segments]]"]),
}


@pytest.mark.parametrize("case", MALFORMED, ids=list(MALFORMED))
def test_malformed_file_names_the_problem(case, tmp_path):
    text, expected = MALFORMED[case]
    path = tmp_path / "broken.toml"
    path.write_text(text)
    with pytest.raises(ValueError) as info:
        load_scene(path)
    message = str(info.value)
    assert message.startswith(str(path)), message
    for part in expected:
        assert part in message, (part, message)
    assert "\n" not in message.strip() or case == "bad TOML", message


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_scene(tmp_path / "nope.toml")


def test_unwritable_scene_is_refused():
    class Custom(pj.StiffeningLaw):
        def __call__(self, elongation, length):
            return jnp.ones_like(elongation)

    seg = pj.Segment(0.1, 0.02, 800.0, stiffening=Custom())
    scene = pj.Scene(pj.Robot([seg]), pj.PCC())
    with pytest.raises(ValueError, match="Custom"):
        scene_to_toml(scene)
    with pytest.raises(ValueError, match="controls"):
        scene_to_toml(pj.Scene(pj.Robot([seg.__class__(0.1, 0.02, 800.0)]), pj.PCC()), [0.1])
