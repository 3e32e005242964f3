"""The fast profile of the scene-space campaign (issue 28): a few structures from the space a
user can write, hundreds of value draws on them (see ``tests/scene_space.py`` for the space and
the properties; ``benchmarks/campaign.py`` runs the deep profile over many structures)."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scene_space import (
    SAME_TIP,
    PropertyFailure,
    Structure,
    build,
    check,
    is_validation_error,
    ran_out_of_steps_on_the_way,
    require_same_tip,
    values,
)

#: Small structures (each one compilation) that still cross the space: a mixed PAC/PCC robot
#: with masses at odd counts, ring and channel tendons in both modes and a follower force; an
#: inextensible polynomial robot with a moment and a Bowden tendon; a float32 PCC robot.
STRUCTURES = {
    "pac-pcc": Structure(
        models=("PAC", "PCC"),
        extensible=(True, True),
        masses=((0, 0.3), (0, 0.7), (1, 0.5)),
        forces=((1, 1.0, True),),
        moments=(),
        tendons=((1, 1.0, "rings", 3, "length", False), (0, 0.8, "channel", 2, "tension", False)),
        gravity=True,
        dtype="float64",
    ),
    "poly": Structure(
        models=("Poly2", "Poly1"),
        extensible=(False, True),
        masses=((1, 0.25), (0, 0.9)),
        forces=(),
        moments=((1, 1.0),),
        tendons=((1, 1.0, "rings", 5, "tension", True),),
        gravity=True,
        dtype="float64",
    ),
    "pac-pcc-conservative": Structure(
        models=("PAC", "PCC"),
        extensible=(True, False),
        masses=((0, 0.3), (0, 0.7), (1, 0.5)),
        forces=((1, 0.5, False),),
        moments=(),
        tendons=((1, 1.0, "rings", 5, "length", False), (0, 0.8, "channel", 2, "tension", False)),
        gravity=True,
        dtype="float64",
    ),
    "pcc-float32": Structure(
        models=("PCC",),
        extensible=(True,),
        masses=((0, 0.5), (0, 1.0), (0, 0.2), (0, 0.6), (0, 0.8)),
        forces=((0, 0.4, False),),
        moments=(),
        tendons=((0, 1.0, "rings", 11, "length", False), (0, 1.0, "rings", 2, "tension", False)),
        gravity=True,
        dtype="float32",
    ),
}

#: The conservative structures, drawn 100 times each: conservative ones compile in 12-18 s on
#: 2 cores, and a draw costs ~0.05 s. Follower forces and dead moments (non-conservative: a
#: larger program, and retries that compile more on a failed draw) are drawn 20 times each.
#: All in CI's slow step; the default step keeps the campaign's regression cases.
CONSERVATIVE = ("pac-pcc-conservative", "pcc-float32")


def _settings(examples: int):
    return settings(
        max_examples=examples,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )


def _draw_and_check(name, data):
    structure = STRUCTURES[name]
    scene, controls = build(structure, data.draw(values(structure)))
    check(scene, controls, structure.dtype)


@pytest.mark.slow  # 100 draws and the programs their outcomes compile (30-45 s a structure)
@pytest.mark.parametrize("name", CONSERVATIVE)
@_settings(100)
@given(data=st.data())
def test_every_draw_solves_or_says_why(name, data):
    _draw_and_check(name, data)


@pytest.mark.long(minutes=3.0)  # the slow step's longest file: handed out first
@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(set(STRUCTURES) - set(CONSERVATIVE)))
@_settings(20)
@given(data=st.data())
def test_every_draw_of_a_non_conservative_scene_solves_or_says_why(name, data):
    _draw_and_check(name, data)


def test_the_structures_cross_the_space():
    kinds = {m for s in STRUCTURES.values() for m in s.models}
    assert {"PAC", "PCC", "Poly1", "Poly2"} <= kinds
    assert {s.dtype for s in STRUCTURES.values()} == {"float32", "float64"}
    routes = {t[2] for s in STRUCTURES.values() for t in s.tendons}
    modes = {t[4] for s in STRUCTURES.values() for t in s.tendons}
    assert routes == {"rings", "channel"} and modes == {"length", "tension"}
    assert any(not all(s.extensible) for s in STRUCTURES.values())
    assert np.any([len(s.masses) in (3, 5) for s in STRUCTURES.values()])  # the counts
    assert set(CONSERVATIVE) < set(STRUCTURES)


def test_found_a_segment_too_light_to_simulate_says_so():
    """Found by the campaign: a density of 1e-308 kg/m passes the ``> 0`` check, and the
    default damping then raised "Damping.stiffness must be finite, got nan"."""
    import pacjax as pj

    segments = [pj.Segment(0.25, 0.1, 100.0, linear_density=d) for d in (0.5, 2.2e-308)]
    scene = pj.Scene(pj.Robot(segments), pj.PCC())
    with pytest.raises(ValueError, match="linear_density .* is too small to simulate"):
        pj.simulate(scene, (0.0, 0.01))


def test_a_mass_matrix_singular_in_float32_names_the_precision():
    """Found by the campaign: three light ``PolynomialCurvature(3)`` segments in float32 were
    refused as "linear_density (0.0529 kg/m) is too small", where float64 simulates them (the
    mass matrix is conditioned at 2e11). Refused whether or not float32's Cholesky factor of it
    exists, which rounding decides (it does on an AMD EPYC): its rest modes are 36 % off."""
    import jax.numpy as jnp

    import pacjax as pj

    segments = [pj.Segment(0.1, 0.01, 200.0, linear_density=0.0529)] * 3
    scene = pj.astype(pj.Scene(pj.Robot(segments), pj.PolynomialCurvature(3)), jnp.float32)
    with pytest.raises(ValueError, match="singular in float32 .* simulate this scene in float64"):
        pj.simulate(scene, (0.0, 0.01))


def test_a_validation_error_is_told_from_a_crash():
    """The campaign's line between a documented validation error (pacjax refusing an input) and
    a crash (an exception from inside JAX, as the knot-layout bug raised from ``einsum``)."""
    import jax.numpy as jnp

    import pacjax as pj

    with pytest.raises(ValueError) as refused:
        pj.Segment(-1.0, 0.1, 100.0)
    assert is_validation_error(refused.value)
    with pytest.raises(ValueError) as crashed:
        jnp.einsum("ij,jk->ik", jnp.ones((2, 3)), jnp.ones((4, 2)))
    assert not is_validation_error(crashed.value)
    assert not is_validation_error(PropertyFailure("a broken property"))


def test_batch_and_single_are_compared_at_the_equilibrium_their_tolerance_leaves():
    """A batch row and its single solve may stop at different points inside the tolerance's
    ball (their paths differ where rounding picks another step); on a soft body that ball is
    wider in position than ``SAME_TIP``. One Newton step from each brings them together; two
    different equilibria stay apart."""
    import equinox as eqx
    import jax.numpy as jnp

    import pacjax as pj

    def scene_with(gravity):
        # Soft, as the campaign's case (EI 5e-4 N m^2), with a lumped mass at the tip.
        segments = [pj.Segment(0.2, 5e-4, 100.0, linear_density=0.05) for _ in range(2)]
        loads = (pj.Gravity(9.81, np.asarray(gravity) / np.linalg.norm(gravity)),)
        loads += (pj.PointMass(0.02, segment=1),)
        return pj.Scene(pj.Robot(segments), pj.PAC(), loads=loads)

    scene = scene_with((1.0, 0.0, -1.0))
    controls = jnp.zeros(0)
    eq = pj.solve_equilibrium(scene, controls)
    assert bool(eq.successful)
    shifted = eq.q * (1.0 + 1e-4)  # as far as the ball's edge on a softer body
    gap = np.linalg.norm(pj.tip_pose(scene, shifted)[0] - pj.tip_pose(scene, eq.q)[0])
    allowed = SAME_TIP["float64"] * float(scene.robot.total_length)
    assert gap > 3 * allowed
    require_same_tip(scene, controls, eq.q, shifted, "float64")

    other = pj.solve_equilibrium(scene_with((1.0, 0.0, -0.9)), controls)
    with pytest.raises(PropertyFailure, match="after a Newton step"):
        require_same_tip(scene, controls, eq.q, other.q, "float64")

    # One of the two out of steps (a slow float32 batch row, met in CI): allowed on the way to
    # the other's equilibrium only.
    def ended(result, q):
        return eqx.tree_at(lambda e: (e.result, e.q), eq, (result, q))

    short = ended(pj.RESULTS.max_steps_reached, shifted)
    assert ran_out_of_steps_on_the_way(scene, controls, eq, short, "float64") == "step limit"
    with pytest.raises(PropertyFailure, match="after a Newton step"):
        elsewhere = ended(pj.RESULTS.max_steps_reached, other.q)
        ran_out_of_steps_on_the_way(scene, controls, eq, elsewhere, "float64")
    stalled = ended(pj.RESULTS.stalled, shifted)
    with pytest.raises(PropertyFailure, match="but single"):
        ran_out_of_steps_on_the_way(scene, controls, eq, stalled, "float64")


def test_two_stable_equilibria_of_one_scene_are_told_apart_from_a_broken_batch():
    """A column past its buckling load, planar (PCC in the paper's frame), has two mirror-image
    bent minima: a batch row and its single solve that reach one each (a start near the
    boundary between the basins, rounding deciding) pass as ``"another equilibrium"`` where
    both succeeded, and fail where that was not asked; a point that is not an equilibrium of
    the scene still fails."""
    import jax.numpy as jnp

    import pacjax as pj

    stiffness, length = 0.05, 0.4
    critical = 3 * stiffness / length**2
    column = pj.Scene(
        pj.Robot([pj.Segment(length, stiffness, axial_stiffness=1e6)]),
        pj.PCC(frame="paper"),
        loads=(pj.Gravity(), pj.PointMass(1.25 * critical / 9.81, 0, 1.0)),
    )
    controls = jnp.zeros(0)
    left, right = (
        pj.solve_equilibrium(column, controls, q0=np.array([bend, 0.0, 0.0]))
        for bend in (-0.3, 0.3)
    )
    assert bool(left.successful) and bool(right.successful)
    assert float(left.q[0]) < -1.0 < 1.0 < float(right.q[0])  # bent to either side
    both = require_same_tip(column, controls, left.q, right.q, "float64", both_stable=True)
    assert both == "another equilibrium"
    with pytest.raises(PropertyFailure, match="after a Newton step"):
        require_same_tip(column, controls, left.q, right.q, "float64")
    with pytest.raises(PropertyFailure, match="after a Newton step"):
        halfway = right.q.at[0].multiply(0.8)  # not an equilibrium: its Newton step moves it
        require_same_tip(column, controls, left.q, halfway, "float64", both_stable=True)
