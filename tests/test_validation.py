"""Bad input raises a clear error that names the offending field, before any solve.

Every check here runs without compiling anything: the equilibrium solver is replaced by a spy
that fails the test if it is ever reached, so an error raised inside the solver (or a bad input
that silently gets through to it) is caught too.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest

import pacjax as pj
import pacjax._statics.batch as batch_module
import pacjax._statics.equilibrium as equilibrium_module

NAN, INF = math.nan, math.inf


@pytest.fixture(autouse=True)
def no_solver(monkeypatch):
    """Fail if validation lets anything reach the (compiled) solver."""

    def spy(*args, **kwargs):
        raise AssertionError("the solver was reached: the input was not rejected beforehand")

    monkeypatch.setattr(equilibrium_module, "_solve_checked", spy)
    monkeypatch.setattr(batch_module, "_solve_chunk", spy)


def _segment(**overrides):
    kwargs = dict(length=0.1, bending_stiffness=0.01, axial_stiffness=100.0)
    kwargs.update(overrides)
    return pj.Segment(**kwargs)


def _scene(n_segments=2, model=None, tendons=None, loads=()):
    robot = pj.Robot([_segment()] * n_segments)
    if tendons is None:
        tendons = (
            pj.Tendon(0, 0.0, 0.01, gain=100.0),
            pj.Tendon(n_segments - 1, 1.0, 0.01, mode="tension"),
        )
    return pj.Scene(robot, model or pj.PCC(), tendons=tendons, loads=loads)


# ------------------------------------------------------------------------------ segments
@pytest.mark.parametrize(
    "field",
    ["length", "bending_stiffness", "axial_stiffness", "torsion_stiffness", "contraction_limit"],
)
@pytest.mark.parametrize("value", [-1.0, 0.0, NAN, INF, -INF])
def test_segment_parameters_must_be_finite_and_positive(field, value):
    with pytest.raises(ValueError, match=f"Segment.{field}"):
        _segment(**{field: value})


@pytest.mark.parametrize("field", ["linear_density", "radius"])
@pytest.mark.parametrize("value", [-1e-3, NAN, INF])
def test_segment_density_and_radius_must_be_finite_and_non_negative(field, value):
    with pytest.raises(ValueError, match=f"Segment.{field}"):
        _segment(**{field: value})
    _segment(**{field: 0.0})  # zero is allowed (massless, or a line body)


def test_segment_contraction_limit_must_be_below_its_length():
    with pytest.raises(ValueError, match="Segment.contraction_limit must be below Segment.length"):
        _segment(contraction_limit=0.1)  # the length: zero length at the stop
    assert float(_segment().contraction_limit) == pytest.approx(0.09)  # default: 90 %
    assert float(_segment(contraction_limit=0.05).contraction_limit) == 0.05


def test_tapered_segment_needs_a_positive_tip_radius_and_base_radius():
    with pytest.raises(ValueError, match="Segment.radius_tip"):
        _segment(radius=0.01, radius_tip=0.0)
    with pytest.raises(ValueError, match="Segment.radius"):
        _segment(radius_tip=0.01)  # no base radius to taper from


def test_segment_stiffening_must_be_a_law():
    with pytest.raises(TypeError, match="Segment.stiffening"):
        _segment(stiffening=2.0)
    with pytest.raises(ValueError, match="ExponentialStiffening.rate"):
        pj.ExponentialStiffening(NAN)


@pytest.mark.parametrize("field", ["length", "bending_stiffness"])
def test_segment_parameters_must_be_scalars(field):
    with pytest.raises(ValueError, match=f"Segment.{field}"):
        _segment(**{field: [0.1, 0.2]})


# ------------------------------------------------------------------------------ robot
def test_robot_needs_segments():
    with pytest.raises(ValueError, match="Robot.segments"):
        pj.Robot([])
    with pytest.raises(TypeError, match=r"Robot.segments\[1\]"):
        pj.Robot([_segment(), 0.1])


@pytest.mark.parametrize(
    "rotation",
    [
        2.0 * np.eye(3),  # not orthogonal
        np.diag([1.0, 1.0, -1.0]),  # a reflection (det -1)
        np.array([[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),  # sheared
        np.full((3, 3), NAN),
    ],
    ids=["scaled", "reflection", "sheared", "nan"],
)
def test_base_rotation_must_be_a_rotation(rotation):
    with pytest.raises(ValueError, match="Robot.base_rotation"):
        pj.Robot([_segment()], base_rotation=rotation)


def test_base_pose_shapes():
    with pytest.raises(ValueError, match=r"Robot.base_rotation must have shape \(3, 3\)"):
        pj.Robot([_segment()], base_rotation=np.eye(2))
    with pytest.raises(ValueError, match=r"Robot.base_position must have shape \(3,\)"):
        pj.Robot([_segment()], base_position=np.zeros(2))
    with pytest.raises(ValueError, match="Robot.base_position must be finite"):
        pj.Robot([_segment()], base_position=[0.0, NAN, 0.0])


# ------------------------------------------------------------------------------ models
@pytest.mark.parametrize("model", [pj.PCC, pj.PAC])
def test_unknown_frame_name(model):
    with pytest.raises(ValueError, match="frame must be one of.*'Paper'"):
        model(frame="Paper")


def test_polynomial_order_and_phi_stiffness():
    with pytest.raises(ValueError, match="PolynomialCurvature order"):
        pj.PolynomialCurvature(order=-1)
    with pytest.raises(ValueError, match="PolynomialCurvature order"):
        pj.PolynomialCurvature(order=1.5)
    with pytest.raises(ValueError, match="phi_stiffness"):
        pj.PAC(phi_stiffness=-1.0)


@pytest.mark.parametrize("model", ["PAC", pj.PAC, None], ids=["name", "class", "none"])
def test_scene_model_must_be_a_strain_model_instance(model):
    with pytest.raises(TypeError, match="Scene.model"):
        pj.Scene(pj.Robot([_segment()]), model)


def test_scene_robot_must_be_a_robot():
    with pytest.raises(TypeError, match="Scene.robot"):
        pj.Scene([_segment()], pj.PAC())


# ------------------------------------------------------------------------------ tendons
def test_tendon_on_a_missing_segment():
    with pytest.raises(ValueError, match=r"Scene.tendons\[1\] is anchored on segment 2"):
        _scene(2, tendons=(pj.Tendon(1, 0.0, 0.01, gain=1.0), pj.Tendon(2, 0.0, 0.01, gain=1.0)))
    with pytest.raises(ValueError, match="Tendon.segment must be >= 0"):
        pj.Tendon(-1, 0.0, 0.01, gain=1.0)
    for bad in (1.0, True, "0"):
        with pytest.raises(TypeError, match="Tendon.segment must be an integer"):
            pj.Tendon(bad, 0.0, 0.01, gain=1.0)


@pytest.mark.parametrize("anchor", [0.0, -0.2, 1.0 + 1e-9, 1.5, NAN])
def test_tendon_anchor_in_half_open_unit_interval(anchor):
    with pytest.raises(ValueError, match=r"Tendon.s \(anchor\) must lie in \(0, 1\]"):
        pj.Tendon(0, 0.0, 0.01, s=anchor, gain=1.0)


@pytest.mark.parametrize(
    "guides", [(0.0, 0.5, 1.2), (-0.1, 0.5), (0.0, NAN), ()], ids=["above", "below", "nan", "none"]
)
def test_tendon_guides_in_unit_interval(guides):
    with pytest.raises(ValueError, match="Tendon.guides"):
        pj.Tendon(0, 0.0, 0.01, guides=guides, gain=1.0)


def test_tendon_mode_gain_offset_angle():
    with pytest.raises(ValueError, match="Tendon.mode must be one of.*'force'"):
        pj.Tendon(0, 0.0, 0.01, mode="force")
    with pytest.raises(ValueError, match="Tendon.gain .* is required"):
        pj.Tendon(0, 0.0, 0.01)
    for gain in (0.0, -5.0, NAN, INF):
        with pytest.raises(ValueError, match="Tendon.gain"):
            pj.Tendon(0, 0.0, 0.01, gain=gain)
    for offset in (-0.01, NAN):
        with pytest.raises(ValueError, match="Tendon.offset"):
            pj.Tendon(0, 0.0, offset, gain=1.0)
    with pytest.raises(ValueError, match="Tendon.offset_end"):
        pj.Tendon(0, 0.0, 0.01, offset_end=-0.01, gain=1.0)
    with pytest.raises(ValueError, match="Tendon.angle"):
        pj.Tendon(0, INF, 0.01, gain=1.0)


# ------------------------------------------------------------------------------ loads
@pytest.mark.parametrize(
    "load",
    [
        lambda: pj.PointMass(0.1, 2),
        lambda: pj.PointForce((1.0, 0.0, 0.0), 5),
        lambda: pj.PointMoment((0.0, 0.0, 0.1), 2, follower=True),
    ],
    ids=["mass", "force", "moment"],
)
def test_load_on_a_missing_segment(load):
    name = load().__class__.__name__
    with pytest.raises(ValueError, match=rf"Scene.loads\[1\] \({name}\) is on segment"):
        _scene(2, loads=(pj.Gravity(), load()))


@pytest.mark.parametrize("kind", [pj.PointMass, pj.PointForce, pj.PointMoment])
def test_load_site_checks(kind):
    value = 0.1 if kind is pj.PointMass else (1.0, 0.0, 0.0)
    with pytest.raises(ValueError, match=f"{kind.__name__}.segment"):
        kind(value, -1)
    for s in (-0.1, 1.5, NAN):
        with pytest.raises(ValueError, match=rf"{kind.__name__}.s must lie in \[0, 1\]"):
            kind(value, 0, s)


def test_load_values():
    for mass in (-0.1, NAN, INF):
        with pytest.raises(ValueError, match="PointMass.mass"):
            pj.PointMass(mass, 0)
    with pytest.raises(ValueError, match=r"PointForce.force must have shape \(3,\)"):
        pj.PointForce((1.0, 0.0), 0)
    with pytest.raises(ValueError, match="PointForce.force must be finite"):
        pj.PointForce((1.0, 0.0, INF), 0)
    with pytest.raises(ValueError, match="PointMoment.moment must be finite"):
        pj.PointMoment((0.0, NAN, 0.0), 0)


def test_gravity_values():
    for g in (-9.81, NAN):
        with pytest.raises(ValueError, match="Gravity.g"):
            pj.Gravity(g=g)
    with pytest.raises(ValueError, match=r"Gravity.direction must have shape \(3,\)"):
        pj.Gravity(direction=(0.0, -1.0))
    with pytest.raises(ValueError, match="Gravity.direction must be a unit vector"):
        pj.Gravity(direction=(0.0, 0.0, -2.0))  # would silently double g


def test_point_mass_needs_gravity_and_one_gravity_at_most():
    with pytest.raises(ValueError, match="PointMass but no Gravity"):
        _scene(loads=(pj.PointMass(0.1, 1),))
    with pytest.raises(ValueError, match="more than one Gravity"):
        _scene(loads=(pj.Gravity(), pj.Gravity(g=1.0)))
    with pytest.raises(TypeError, match=r"Scene.loads\[0\] must be one of"):
        _scene(loads=("gravity",))


def test_scene_structure_settings_and_markers():
    robot = pj.Robot([_segment()])
    with pytest.raises(ValueError, match="Scene.quadrature_points"):
        pj.Scene(robot, pj.PAC(), quadrature_points=0)
    with pytest.raises(ValueError, match="Scene.rotation_substeps"):
        pj.Scene(robot, pj.PAC(), rotation_substeps=0)
    with pytest.raises(ValueError, match=r"Scene.knot_grid must be >= 1 in both entries"):
        pj.Scene(robot, pj.PAC(), knot_grid=(4, 0))
    for bad in (4, (4, 3, 2), (4, 2.5), "43"):
        with pytest.raises(TypeError, match=r"Scene.knot_grid must be"):
            pj.Scene(robot, pj.PAC(), knot_grid=bad)
    with pytest.raises(ValueError, match=r"Scene.markers\[0\]: segment 1 does not exist"):
        pj.Scene(robot, pj.PAC(), markers=[(1, 0.5)])
    with pytest.raises(ValueError, match=r"Scene.markers\[1\]: s must lie in \[0, 1\]"):
        pj.Scene(robot, pj.PAC(), markers=[(0, 0.5), (0, 1.5)])
    with pytest.raises(ValueError, match=r"Scene.markers\[0\]: offset"):
        pj.Scene(robot, pj.PAC(), markers=[(0, 0.5, (0.0, NAN, 0.0))])


def test_kinematic_queries():
    scene = _scene()
    q = jnp.zeros(scene.n_dofs)
    with pytest.raises(ValueError, match=r"sites\[0\]: segment 5 does not exist"):
        pj.markers(scene, q, [(5, 0.5)])
    with pytest.raises(ValueError, match="no marker sites"):
        pj.markers(scene, q)
    with pytest.raises(ValueError, match="n_points"):
        pj.backbone(scene, q, 1)


# ------------------------------------------------------------------------------ solve inputs
@pytest.mark.parametrize(
    "controls",
    [[NAN, 1.0], [0.01, INF], np.array([0.0, -INF])],
    ids=["nan", "inf", "-inf"],
)
def test_non_finite_controls(controls):
    with pytest.raises(ValueError, match="controls contain NaN or infinite values"):
        pj.solve_equilibrium(_scene(), controls)


@pytest.mark.filterwarnings("error")
def test_controls_as_a_python_list_are_validated_without_warnings():
    """A list is the most natural way to pass a few controls (JAX deprecates ``jnp.shape`` of a
    list: it will become an error)."""
    with pytest.raises(ValueError, match="controls contain NaN or infinite values"):
        pj.solve_equilibrium(_scene(), [NAN, 1.0])
    with pytest.raises(ValueError, match=r"controls\[1\] is a tension"):
        pj.solve_equilibrium(_scene(), [0.0, -1.0])


@pytest.mark.parametrize(
    "controls",
    [0.0, np.zeros(1), np.zeros(3), np.zeros((2, 3))],
    ids=["()", "(1,)", "(3,)", "(2,3)"],
)
def test_wrong_control_shapes(controls):
    with pytest.raises(ValueError, match=r"controls must have shape .*2"):
        pj.solve_equilibrium(_scene(), controls)


def test_batched_controls_are_not_silently_collapsed():
    """A (batch, n_tendons) array is not a valid input of a single solve: rather than solving
    with some row of it, ``solve_equilibrium`` must reject it (or solve every row)."""
    with pytest.raises(ValueError, match="controls"):
        pj.solve_equilibrium(_scene(), np.zeros((3, 2)))


def test_negative_tension_controls():
    # The second tendon is in tension mode: tendons never push.
    with pytest.raises(ValueError, match=r"controls\[1\] is a tension and must be >= 0"):
        pj.solve_equilibrium(_scene(), [0.0, -0.5])


def test_initial_configuration():
    scene = _scene()
    with pytest.raises(ValueError, match=r"q0 must have shape .*6"):
        pj.solve_equilibrium(scene, None, np.zeros(5))
    with pytest.raises(ValueError, match="q0 contains NaN"):
        pj.solve_equilibrium(scene, None, np.full(6, NAN))
    with pytest.raises(ValueError, match="q0"):
        pj.solve_equilibrium(scene, None, np.zeros((2, 6)))
    # Segment 1 contracted past its stop (0.09 m of 0.1 m): infinite energy at the start.
    q0 = np.zeros(6)
    q0[5] = -0.095
    with pytest.raises(ValueError, match="q0 contracts segment 1 by 0.095 m"):
        pj.solve_equilibrium(scene, None, q0)
    with pytest.raises(ValueError, match=r"q0 \(row 1\) contracts segment 1"):
        pj.solve_batch(scene, np.zeros((2, 2)), np.stack([np.zeros(6), q0]))


def test_solver_options_and_scene_type():
    scene = _scene()
    with pytest.raises(ValueError, match="method must be 'ptc' or 'flow'"):
        pj.solve_equilibrium(scene, method="newton")
    for tol in (0.0, -1.0, NAN):
        with pytest.raises(ValueError, match="tol must be finite and > 0"):
            pj.solve_equilibrium(scene, tol=tol)
    with pytest.raises(ValueError, match="max_steps"):
        pj.solve_equilibrium(scene, max_steps=0)
    with pytest.raises(ValueError, match="escapes"):
        pj.solve_equilibrium(scene, escapes=-1)
    with pytest.raises(TypeError, match="bogus"):
        pj.solve_equilibrium(scene, bogus=1)
    with pytest.raises(TypeError, match="scene must be a pacjax.Scene"):
        pj.solve_equilibrium(pj.Robot([_segment()]))


def test_preset_arguments():
    with pytest.raises(ValueError, match="mount must be one of"):
        pj.presets.stella2023(mount="sideways")
    with pytest.raises(ValueError, match="n_sections"):
        pj.presets.stella2023(n_sections=0)


# ------------------------------------------------------------------------------ types (issue 6)
NOT_NUMBERS = ["stiff", None, True, 1.0 + 2.0j, [0.1, "a"]]


@pytest.mark.parametrize("value", NOT_NUMBERS, ids=["str", "None", "bool", "complex", "mixed"])
@pytest.mark.parametrize("field", ["length", "bending_stiffness", "axial_stiffness", "radius"])
def test_segment_parameters_must_be_real_numbers(field, value):
    with pytest.raises(TypeError, match=f"Segment.{field}"):
        _segment(**{field: value})


def test_segment_taper_and_stiffening_types():
    with pytest.raises(TypeError, match="Segment.radius_tip"):
        _segment(radius=0.01, radius_tip="thin")
    with pytest.raises(ValueError, match="ExponentialStiffening.rate must be a single number"):
        pj.ExponentialStiffening([1.0, 2.0])
    with pytest.raises(TypeError, match="ExponentialStiffening.rate"):
        pj.ExponentialStiffening("fast")


def test_robot_types():
    with pytest.raises(TypeError, match="Robot.segments must be a sequence"):
        pj.Robot(_segment())
    with pytest.raises(TypeError, match="Robot.base_rotation"):
        pj.Robot([_segment()], base_rotation="identity")
    with pytest.raises(TypeError, match="Robot.base_position"):
        pj.Robot([_segment()], base_position=[0.0, None, 0.0])


def test_tendon_types_and_shapes():
    with pytest.raises(TypeError, match="Tendon.s"):
        pj.Tendon(0, 0.0, 0.01, s="tip", gain=1.0)
    with pytest.raises(TypeError, match="Tendon.guides must be a sequence"):
        pj.Tendon(0, 0.0, 0.01, guides=0.5, gain=1.0)
    with pytest.raises(TypeError, match="Tendon.guides"):
        pj.Tendon(0, 0.0, 0.01, guides=(0.0, "half"), gain=1.0)
    with pytest.raises(TypeError, match="Tendon.bowden"):
        pj.Tendon(0, 0.0, 0.01, bowden="no", gain=1.0)
    with pytest.raises(TypeError, match="Tendon.angle"):
        pj.Tendon(0, "north", 0.01, gain=1.0)
    with pytest.raises(TypeError, match="Tendon.offset"):
        pj.Tendon(0, 0.0, None, gain=1.0)
    with pytest.raises(ValueError, match="Tendon.gain must be a single number"):
        pj.Tendon(0, 0.0, 0.01, gain=[1.0, 2.0])
    with pytest.raises(ValueError, match="Tendon.offset_end must be a single number"):
        pj.Tendon(0, 0.0, 0.01, offset_end=[0.01, 0.02], gain=1.0)
    # A gain given to a tension-mode tendon is unused, but a NaN there is still an error.
    with pytest.raises(ValueError, match="Tendon.gain must be finite"):
        pj.Tendon(0, 0.0, 0.01, mode="tension", gain=NAN)


def test_load_types():
    with pytest.raises(TypeError, match="PointMass.mass"):
        pj.PointMass("heavy", 0)
    with pytest.raises(TypeError, match="PointMass.s"):
        pj.PointMass(0.1, 0, "tip")
    with pytest.raises(TypeError, match="PointForce.force"):
        pj.PointForce("up", 0)
    with pytest.raises(TypeError, match="PointForce.follower"):
        pj.PointForce((1.0, 0.0, 0.0), 0, follower="yes")
    with pytest.raises(TypeError, match="PointMoment.follower"):
        pj.PointMoment((1.0, 0.0, 0.0), 0, follower=1)
    with pytest.raises(TypeError, match="Gravity.g"):
        pj.Gravity(g="earth")
    with pytest.raises(ValueError, match="Gravity.g must be finite"):
        pj.Gravity(g=INF)


def test_scene_containers_and_counts():
    robot = pj.Robot([_segment()])
    with pytest.raises(TypeError, match="Scene.tendons must be a sequence of Tendons, got Tendon"):
        pj.Scene(robot, pj.PCC(), tendons=pj.Tendon(0, 0.0, 0.01, gain=1.0))
    with pytest.raises(TypeError, match="Scene.loads must be a sequence of loads, got Gravity"):
        pj.Scene(robot, pj.PCC(), loads=pj.Gravity())
    for bad in (8.7, "8", True):
        with pytest.raises(TypeError, match="Scene.quadrature_points must be an integer"):
            pj.Scene(robot, pj.PCC(), quadrature_points=bad)
    with pytest.raises(TypeError, match="Scene.rotation_substeps must be an integer"):
        pj.Scene(robot, pj.PCC(), rotation_substeps=2.5)
    with pytest.raises(TypeError, match="Scene.markers must be a sequence"):
        pj.Scene(robot, pj.PCC(), markers=5)
    with pytest.raises(ValueError, match=r"Scene.markers\[0\]: s must lie in \[0, 1\]"):
        pj.Scene(robot, pj.PCC(), markers=[(0, "mid")])
    with pytest.raises(ValueError, match=r"Scene.markers\[0\]: offset"):
        pj.Scene(robot, pj.PCC(), markers=[(0, 0.5, 0.01)])
    with pytest.raises(ValueError, match=r"Scene.markers\[0\]: segment True"):
        pj.Scene(robot, pj.PCC(), markers=[(True, 0.5)])


@pytest.mark.parametrize(
    "q, error, match",
    [
        (np.full(6, NAN), ValueError, "q contains NaN or infinite values"),
        (np.array([0.0, 0.0, INF, 0.0, 0.0, 0.0]), ValueError, "q contains NaN"),
        (np.zeros((2, 6)), ValueError, r"q must have shape \(6,\)"),
        (np.zeros(5), ValueError, r"q must have shape \(6,\)"),
        (["a"] * 6, TypeError, "q must be an array of real numbers"),
        (None, TypeError, "q must be an array"),
    ],
    ids=["nan", "inf", "batched", "short", "strings", "None"],
)
def test_kinematic_queries_check_q(q, error, match):
    scene = _scene()
    for query in (
        lambda: pj.backbone(scene, q),
        lambda: pj.markers(scene, q, [(0, 0.5)]),
        lambda: pj.tip_pose(scene, q),
        lambda: pj.tendon_tensions(scene, q, np.zeros(2)),
    ):
        with pytest.raises(error, match=match):
            query()


def test_kinematic_query_arguments():
    scene = _scene()
    q = np.zeros(scene.n_dofs)
    for bad in (2.5, "10", True):
        with pytest.raises(TypeError, match="n_points must be an integer"):
            pj.backbone(scene, q, bad)
    with pytest.raises(TypeError, match="scene must be a pacjax.Scene"):
        pj.backbone(scene.robot, q)
    with pytest.raises(TypeError, match="sites must be a sequence"):
        pj.markers(scene, q, "tip")
    with pytest.raises(ValueError, match=r"sites\[0\]: s must lie"):
        pj.markers(scene, q, [(0, "mid")])
    with pytest.raises(ValueError, match=r"controls must have shape \(2,\)"):
        pj.tendon_tensions(scene, q, np.zeros(3))
    with pytest.raises(ValueError, match="controls contain NaN"):
        pj.tendon_tensions(scene, q, [NAN, 0.0])
    with pytest.raises(TypeError, match="dtype must be a floating dtype"):
        pj.astype(scene, jnp.int32)


def test_batch_inputs():
    scene = _scene()
    with pytest.raises(ValueError, match=r"controls_batch must have shape \(batch, 2\)"):
        pj.solve_batch(scene, np.zeros(2))
    with pytest.raises(ValueError, match="controls contain NaN"):
        pj.solve_batch(scene, [[NAN, 0.0]])
    with pytest.raises(ValueError, match=r"q0 must have shape"):
        pj.solve_batch(scene, np.zeros((3, 2)), np.zeros((2, 6)))
    with pytest.raises(ValueError, match="q0 contains NaN"):
        pj.solve_batch(scene, np.zeros((1, 2)), np.full(6, NAN))
    with pytest.raises(ValueError, match="params= needs update="):
        pj.solve_batch(scene, np.zeros((2, 2)), params=np.zeros(2))
    with pytest.raises(ValueError, match="leading axis of 2"):
        pj.solve_batch(scene, np.zeros((2, 2)), params=np.zeros(3), update=lambda s, p: s)


# ------------------------------------------------------------------ solver options and batch
@pytest.mark.parametrize(
    "options, match",
    [
        ({"max_steps": 2.5}, "max_steps must be an integer"),
        ({"escapes": True}, "escapes must be an integer"),
        ({"initial_dt": 0.0}, "initial_dt must be finite and > 0"),
        ({"max_dt": float("nan")}, "max_dt must be finite and > 0"),
        ({"escape_size": -0.1}, "escape_size must be finite and > 0"),
        ({"stability_tol": float("inf")}, "stability_tol must be finite and > 0"),
        ({"tol": "small"}, "tol must be a number"),
        ({"flow_solver": "Kvaerno5"}, "flow_solver must be a diffrax solver"),
        ({"hessian": "exact"}, "hessian must be 'structured' or 'autodiff'"),
    ],
)
def test_solver_options_are_checked(options, match):
    with pytest.raises((TypeError, ValueError), match=match):
        pj.SolverOptions(**options)


def test_batch_arguments_are_checked():
    scene = _scene()
    with pytest.raises(TypeError, match="scene must be a pacjax.Scene"):
        pj.solve_batch("scene.toml", np.zeros((2, 2)))
    with pytest.raises(ValueError, match="chunk_size must be >= 1"):
        pj.solve_batch(scene, np.zeros((2, 2)), chunk_size=0)
    with pytest.raises(TypeError, match="controls_batch must be an array of real numbers"):
        pj.solve_batch(scene, [["a", "b"], ["c", "d"]])
    with pytest.raises(TypeError, match="controls must be an array of real numbers"):
        pj.solve_equilibrium(scene, ["a", "b"])
    with pytest.raises(TypeError, match="q0 must be an array of real numbers"):
        pj.solve_equilibrium(scene, [0.0, 0.0], q0=["x"] * 6)
