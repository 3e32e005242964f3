"""Stability of equilibria: buckling of a clamped column under a tip mass."""

import equinox as eqx
import numpy as np
import pytest

import pacjax as pj

EI = 0.05
LENGTH = 0.4
G = 9.81
P_CRITICAL = np.pi**2 * EI / (4 * LENGTH**2)  # clamped-free column, N


@pytest.fixture(scope="module")
def column():
    """Upright massless column of two cubic-curvature segments with a tip mass (nearly
    inextensible: axial stiffness 1e6 N/m)."""
    seg = pj.Segment(LENGTH / 2, EI, axial_stiffness=1e6)
    return pj.Scene(
        pj.Robot([seg, seg]),
        pj.PolynomialCurvature(3),
        loads=(pj.Gravity(), pj.PointMass(0.0, 1, 1.0)),
    )


def _with_load(scene, load):
    return eqx.tree_at(lambda s: s.loads[1].mass, scene, load / G)


@pytest.mark.parametrize("ratio", [0.98, 0.5])
def test_straight_column_below_critical_load_is_stable(column, ratio):
    eq = pj.solve_equilibrium(_with_load(column, ratio * P_CRITICAL), escapes=0)
    assert eq.converged and eq.stable
    assert float(eq.min_hessian_eigenvalue) > 0
    np.testing.assert_allclose(pj.tip_pose(column, eq.q)[0][:2], 0.0, atol=1e-12)


def test_straight_column_above_critical_load_is_flagged_unstable(column):
    eq = pj.solve_equilibrium(_with_load(column, 1.02 * P_CRITICAL), escapes=0)
    assert eq.converged  # the straight state is an equilibrium...
    assert not eq.stable  # ...but a saddle
    assert float(eq.min_hessian_eigenvalue) < 0


def test_buckled_column_is_found_and_stable(column):
    scene = _with_load(column, 1.5 * P_CRITICAL)
    eq = pj.solve_equilibrium(scene)  # escapes the straight saddle by default
    assert eq.converged and eq.stable
    tip = np.asarray(pj.tip_pose(scene, eq.q)[0])
    assert np.hypot(tip[0], tip[1]) > 0.05 * LENGTH
    straight = pj.solve_equilibrium(scene, escapes=0)
    assert float(eq.energy) < float(straight.energy)


def test_critical_load_within_two_percent(column):
    """Bisect the load at which the straight state loses stability."""
    low, high = 0.5 * P_CRITICAL, 1.5 * P_CRITICAL
    for _ in range(8):
        mid = 0.5 * (low + high)
        eq = pj.solve_equilibrium(_with_load(column, mid), escapes=0)
        assert eq.converged
        low, high = (mid, high) if bool(eq.stable) else (low, mid)
    assert abs(0.5 * (low + high) / P_CRITICAL - 1.0) < 0.02
