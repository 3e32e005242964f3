"""Batched solves agree with single solves; chunking and warm starts do not change results."""

import equinox as eqx
import numpy as np
import pytest

import pacjax as pj


@pytest.fixture(scope="module")
def scene():
    seg = pj.Segment(0.15, 0.05, 2000.0, linear_density=0.3)
    tendons = [pj.Tendon(0, a, 0.02, gain=5e3) for a in (0.0, 2 * np.pi / 3, 4 * np.pi / 3)]
    return pj.Scene(
        pj.Robot([seg]),
        pj.PolynomialCurvature(1),
        tendons=tendons,
        loads=(pj.Gravity(direction=(1.0, 0.0, 0.0)), pj.PointMass(0.1, 0)),
    )


def test_batch_matches_single_solves(scene):
    commands = np.random.default_rng(0).uniform(0.0, 0.01, (5, 3))
    batch = pj.solve_batch(scene, commands, chunk_size=4, warm_start=True)
    assert batch.q.shape == (5, scene.n_dofs)
    assert np.all(batch.converged)
    for i, u in enumerate(commands):
        single = pj.solve_equilibrium(scene, u)
        np.testing.assert_allclose(batch.q[i], single.q, atol=1e-9)


def test_batch_over_payloads(scene):
    masses = np.array([0.0, 0.1, 0.3])
    commands = np.zeros((3, 3))
    batch = pj.solve_batch(
        scene,
        commands,
        params=masses,
        update=lambda sc, m: eqx.tree_at(lambda s: s.loads[1].mass, sc, m),
        chunk_size=4,
    )
    tips = [np.asarray(pj.tip_pose(scene, q)[0]) for q in batch.q]
    # Gravity along +x: a heavier payload pulls the tip further along x.
    assert tips[0][0] < tips[1][0] < tips[2][0]


def test_batch_rejects_bad_shapes(scene):
    with pytest.raises(ValueError, match="controls must have shape"):
        pj.solve_batch(scene, np.zeros((4, 2)))
    with pytest.raises(ValueError, match="q0 must have shape"):
        pj.solve_batch(scene, np.zeros((4, 3)), q0=np.zeros((3, scene.n_dofs)))
