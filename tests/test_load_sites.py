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
    [(pj.PCC(), 3, "mass"), (pj.PAC(), 5, "force"), (pj.PolynomialCurvature(1), 7, "mass")],
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
