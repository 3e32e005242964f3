"""Several equilibria from several starts: a clamped column past its buckling load.

The column is one PCC segment in the paper's frame, where ``phi`` twists the frame and has the
physical torsion stiffness ``GJ / L``: the bending plane is then pinned and the problem is
planar, with exactly three equilibria past the critical load: the straight saddle and two
mirror-image bent minima. (In an axisymmetric model, a torsion-free frame or polynomial
curvature, the bent states form a circle of equilibria, one per bending direction.)
"""

import numpy as np
import pytest

import pacjax as pj

# The whole file runs in CI's slow step:
# several-start batches: minutes of compilation on 2 cores.
pytestmark = pytest.mark.slow

EI = 0.05
LENGTH = 0.4
G = 9.81
P_CRITICAL_PCC = 3 * EI / LENGTH**2  # one constant-curvature segment: 0.5 k c^2 = P L c^2 / 6


@pytest.fixture(scope="module")
def column():
    seg = pj.Segment(LENGTH, EI, axial_stiffness=1e6)
    return pj.Scene(
        pj.Robot([seg]),
        pj.PCC(frame="paper"),
        loads=(pj.Gravity(), pj.PointMass(1.25 * P_CRITICAL_PCC / G, 0, 1.0)),
    )


@pytest.fixture(scope="module")
def found(column):
    return pj.find_equilibria(column, n_starts=12, seed=0)


def test_buckled_column_has_two_mirror_bent_minima_and_a_straight_saddle(column, found):
    print(found.summary())
    assert len(found) == 3
    assert found.n_failed == 0 and int(np.sum(found.hits)) == 12
    energy = np.asarray(found.energy)
    assert np.all(np.diff(energy) >= 0)  # sorted, lowest first

    bent, straight = [found[0], found[1]], found[2]
    tips = np.array([np.asarray(pj.tip_pose(column, eq.q)[0]) for eq in bent])
    for eq in bent:
        assert bool(eq.converged) and bool(eq.stable)
        assert float(eq.min_hessian_eigenvalue) > 0
    # Mirror images: same energy and height, opposite sideways deflection in the x-z plane.
    np.testing.assert_allclose(energy[0], energy[1], rtol=1e-12)
    np.testing.assert_allclose(tips[0, 2], tips[1, 2], rtol=1e-9)
    np.testing.assert_allclose(tips[0, :2], -tips[1, :2], atol=1e-9)
    assert abs(tips[0, 0]) > 0.1 * LENGTH and abs(tips[0, 1]) < 1e-9

    # The straight state is an equilibrium, flagged unstable, of higher energy.
    assert bool(straight.converged) and not bool(straight.stable)
    assert float(straight.min_hessian_eigenvalue) < 0
    np.testing.assert_allclose(np.asarray(straight.q)[0], 0.0, atol=1e-12)
    assert float(straight.energy) > energy[0]


def test_below_the_critical_load_the_straight_state_is_the_only_one(column):
    import equinox as eqx

    light = eqx.tree_at(lambda s: s.loads[1].mass, column, 0.8 * P_CRITICAL_PCC / G)
    found = pj.find_equilibria(light, n_starts=12, seed=1)  # same batch shape: no recompile
    assert len(found) == 1
    assert bool(found[0].stable)
    np.testing.assert_allclose(np.asarray(found.q)[0, 0], 0.0, atol=1e-9)


def test_bad_arguments_are_rejected_before_solving(column, found):
    with pytest.raises(ValueError, match="n_starts"):
        pj.find_equilibria(column, n_starts=0)
    with pytest.raises(TypeError, match="n_starts"):
        pj.find_equilibria(column, n_starts=2.5)
    with pytest.raises(ValueError, match="seed"):
        pj.find_equilibria(column, seed=-1)
    for spread in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="spread"):
            pj.find_equilibria(column, spread=spread)
    with pytest.raises(ValueError, match="controls"):
        pj.find_equilibria(column, [0.1])
    with pytest.raises(TypeError, match="scene"):
        pj.find_equilibria(column.robot)
    with pytest.raises(IndexError):
        found[5]


def test_the_default_starts_find_the_curled_loop_of_a_hanging_cable():
    """A hanging cable with a tip mass, curled by a tendon at 1-3 N, has a mild bend and a
    loop curled through more than a turn. With one spread of 1 rad even 170 starts found only
    the bend; the default spreads (0.5 rad to 2 pi) find both from 16."""
    seg = pj.Segment(0.3, 9e-4, 1e3, linear_density=1e-3, extensible=False)
    cable = pj.Scene(
        pj.Robot([seg], base_rotation=pj.presets.MOUNTS["hanging"]),
        pj.PCC(),
        tendons=[pj.Tendon(0, 0.0, 0.01, mode="tension", routing="channel")],
        loads=[pj.Gravity(), pj.PointMass(0.05, 0)],
    )
    for tension in (1.0, 2.0, 3.0):
        found = pj.find_equilibria(cable, [tension])
        bends = np.abs(np.asarray(found.q)[np.asarray(found.stable), 0])
        assert np.any(bends < 1.0) and np.any((bends > 7.0) & (bends < 8.5)), bends
    narrow = pj.find_equilibria(cable, [2.0], n_starts=170, spread=1.0)
    assert np.all(np.abs(np.asarray(narrow.q)[np.asarray(narrow.stable), 0]) < 1.0)
