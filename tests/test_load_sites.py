"""Load sites off the default knot grid: a hanging cable of lumped masses or forces.

Known load sites become knots of the kinematics; the scene's constants (the mass beyond every
position node) are computed with those knots. Where a solver step stopped the gradients of the
whole problem (``jax.lax.stop_gradient``) or took its shapes (``jax.eval_shape``), the sites
became traced values, the knots fell back to the default grid, and 3, 5, 6, 7, 9 or 16 sites
on one segment failed with "Size of label 'k' for operand 1 (8) does not match previous terms
(9)" while 2, 4 or 8 (on the default grid) worked."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from marks import slow

import pacjax as pj
from pacjax._model.inputs import as_traced_leaves, frozen, static_load_sites

HANGING = np.diag([1.0, -1.0, -1.0])


def _cable(model, count, kind):
    segment = pj.Segment(0.3, 0.02, 800.0, linear_density=0.05, radius=0.01)
    sites = np.linspace(0.0, 1.0, count + 1)[1:]
    if kind == "mass":
        loads = tuple(pj.PointMass(0.01, 0, float(s)) for s in sites)
    else:
        loads = tuple(pj.PointForce((0.0, 0.0, -0.1), 0, float(s)) for s in sites)
    return pj.Scene(
        pj.Robot((segment,), base_rotation=HANGING), model, loads=(pj.Gravity(), *loads)
    )


@pytest.mark.parametrize(
    "model, count, kind",
    [(pj.PCC(), 3, "mass"), (pj.PAC(), 5, "force"), slow(pj.PolynomialCurvature(1), 7, "mass")],
    ids=["PCC-3-masses", "PAC-5-forces", "Poly1-7-masses"],
)
def test_single_and_batch_solves_with_sites_off_the_grid(model, count, kind):
    scene = _cable(model, count, kind)
    eq = pj.solve_equilibrium(scene)
    assert bool(eq.successful) and bool(eq.stable), eq.reason
    batch = pj.solve_batch(scene, np.zeros((2, 0)), progress=False)
    assert np.all(np.asarray(batch.successful))
    np.testing.assert_allclose(np.asarray(batch.q[0]), np.asarray(eq.q), atol=1e-12)


def test_frozen_keeps_static_sites_python_numbers_inside_jit():
    scene = static_load_sites(_cable(pj.PCC(), 3, "mass"))
    seen = {}

    @jax.jit
    def f(x):
        seen["frozen"] = [load.s for load in frozen(scene).loads[1:]]
        seen["stop_gradient"] = [load.s for load in jax.lax.stop_gradient(scene).loads[1:]]
        return x

    f(1.0)
    assert all(isinstance(s, float) for s in seen["frozen"])
    # what the solver used to do: the sites became traced values
    assert not any(isinstance(s, float) for s in seen["stop_gradient"])


def test_known_sites_stay_knots_when_the_solve_is_traced():
    """A solve inside a trace (the user's ``jit``, the inverse solver's Levenberg-Marquardt
    residual) gets its scene as traced leaves, but the load sites given as numbers are still
    Python numbers, hence knots: made arrays first, they were traced sites, each with its own
    frame integration and Hessian block (10,935 instead of 6,519 equations for the paper's
    robot), and the traced solve agrees with the plain one."""
    # Sites as Python numbers, as the inverse solver passes its scene.
    scene = static_load_sites(pj.presets.stella2023(pj.PAC(), tip_mass=0.2))
    u = jnp.full(scene.n_tendons, 0.01)

    @eqx.filter_jit
    def traced(sc, controls):
        prepared = static_load_sites(as_traced_leaves(sc, jnp.float64))
        sites = [load.s for load in prepared.loads if hasattr(load, "s")]
        assert sites and all(isinstance(s, float) for s in sites), sites
        assert not prepared.energy_plan().points.traced
        return pj.solve_equilibrium(sc, controls).q

    np.testing.assert_allclose(traced(scene, u), pj.solve_equilibrium(scene, u).q, atol=1e-12)


@pytest.mark.parametrize("model", [pj.PAC(), pj.PolynomialCurvature(2)], ids=["PAC", "Poly2"])
def test_a_traced_site_is_as_accurate_as_a_known_site_on_a_curled_body(model):
    """A site known only at run time (a differentiated or jit-argument site) has its frame
    integrated over ``[0, s]`` as finely as the knot path integrates a segment. One 8-point
    Gauss-Legendre rule over ``[0, s]`` put a site of a PAC segment curled by 9.5 rad 0.17 m from
    where it is (a campaign draw whose check, run under ``jit``, took the traced path)."""
    robot = pj.Robot([pj.Segment(0.25, 0.02, 1e3, 0.1), pj.Segment(0.2, 0.02, 1e3, 0.1)])
    segments, sites = [0, 0, 1, 1], np.asarray([0.576, 0.913, 0.5, 1.0])

    def positions(scene):
        q = np.zeros(scene.n_dofs)
        d = scene.n_dofs // 2
        # About 9.5 rad of bending on the first segment, then a second plane.
        q[:3] = (-38.0, -0.7, 1.1) if isinstance(model, pj.PAC) else (-38.0, 20.0, 5.0)
        q[d : d + 3] = (6.0, -3.0, 0.4)
        q = jnp.asarray(q)
        # Closed over, the sites stay Python floats (known); passed in, they are traced.
        known = jax.jit(lambda: scene.frames(q, segments, sites))()[1]
        traced = jax.jit(lambda s: scene.frames(q, segments, s))(jnp.asarray(sites))[1]
        return np.asarray(known), np.asarray(traced)

    fine_known, fine_traced = positions(pj.Scene(robot, model, rotation_substeps=64))
    np.testing.assert_allclose(fine_traced, fine_known, atol=1e-12)
    known, traced = positions(pj.Scene(robot, model))
    # The default cut's own error at this curl: about 2e-6 m on both paths.
    assert np.abs(known - fine_known).max() < 5e-6
    assert np.abs(traced - fine_known).max() < 5e-6
