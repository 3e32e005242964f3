"""The pseudo-transient continuation root finder on its own, and the follower-force residual."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import optimistix as optx

import pacjax as pj
from pacjax._equilibrium import static_load_sites
from pacjax._ptc import PseudoTransientContinuation
from pacjax._solution import STALLED


def test_no_descent_at_the_smallest_step_is_reported_stalled_early():
    # r(y) = y^2 + 1 has no root; |r|^2 has its minimum at y = 0, where r = 1 and the flow
    # direction -r raises |r|^2. The continuation must say it stalled, not creep on to its step
    # limit (it used to run all 300 steps there).
    def fn(y, args):
        r = y**2 + 1.0
        return r, (0.5 * jnp.sum(r * r), jnp.ones_like(y))

    solver = PseudoTransientContinuation(rtol=0.0, atol=1e-10, symmetric=False)
    sol = optx.root_find(fn, solver, jnp.ones(3), has_aux=True, max_steps=300, throw=False)
    assert int(sol.state.code) == STALLED
    assert int(sol.stats["num_steps"]) < 40, int(sol.stats["num_steps"])
    assert np.all(np.abs(np.asarray(sol.value) ** 2 + 1.0) > 0.5)


def test_follower_force_residual_is_the_same_under_jit():
    # The follower force's site is known (the solver makes it a Python float first): under jit
    # its frames must come from the same knot path as outside it. Stacked into a tracer, the
    # site took the grid path (here 5e-6 apart), and every solver step of a follower scene
    # cost several times more.
    force = pj.PointForce((0.0, 0.5, 2.0), segment=1, s=0.7, follower=True)
    robot = pj.Robot([pj.Segment(0.1, 0.02, 1e3, 0.1), pj.Segment(0.1, 0.02, 1e3, 0.1)])
    scene = pj.Scene(robot, pj.PolynomialCurvature(order=2), loads=(force,))
    scene = static_load_sites(scene)
    q = jnp.asarray(np.random.default_rng(0).normal(0.0, 1.0, scene.n_dofs))
    eager = np.asarray(scene.residual(q, None))
    jitted = np.asarray(eqx.filter_jit(lambda sc, x: sc.residual(x, None))(scene, q))
    np.testing.assert_allclose(jitted, eager, rtol=1e-13, atol=1e-13 * np.abs(eager).max())
