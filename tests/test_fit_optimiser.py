"""The safeguards of the fit's Levenberg-Marquardt loop
(pacjax._identify.optimise.LevenbergMarquardt):
a bounded step and a damping that follows the gain ratio."""

import numpy as np
import pytest

from pacjax._identify.optimise import LevenbergMarquardt as _LevenbergMarquardt

UNBOUNDED = (np.full(3, -np.inf), np.full(3, np.inf))


def _problem():
    rng = np.random.default_rng(0)
    jac = rng.normal(size=(20, 3)) * np.array([1.0, 1e-2, 1.0])  # one weak direction
    return jac, rng.normal(size=20) * 50.0


def test_step_is_cut_back_to_the_radius_and_predicts_a_decrease():
    jac, r = _problem()
    lm = _LevenbergMarquardt()
    full = np.linalg.lstsq(jac, -r, rcond=None)[0]
    assert np.max(np.abs(full)) > lm.radius  # the Gauss-Newton step would leave the region
    step, predicted = lm.step(jac, r, np.zeros(3), UNBOUNDED)
    assert np.max(np.abs(step)) == pytest.approx(lm.radius)
    assert predicted > 0
    assert step @ (jac.T @ r) < 0  # downhill


def test_damping_follows_the_gain_ratio():
    lm = _LevenbergMarquardt()
    d0 = lm.damping
    assert lm.update(1.0, 1.0, ok=True)  # good model: less damping, larger region
    assert lm.damping == pytest.approx(d0 / 3.0)
    assert lm.radius == pytest.approx(2.0)
    d1 = lm.damping
    assert lm.update(0.1, 1.0, ok=True)  # accepted, but the model was poor: more damping
    assert lm.damping > d1
    assert lm.radius == pytest.approx(0.5)
    d2 = lm.damping
    assert not lm.update(0.5, 0.5, ok=False)  # failed equilibria: rejected
    assert not lm.update(-1.0, 0.25, ok=True)  # the loss rose: rejected
    assert lm.damping == pytest.approx(d2 * 2.0 * 4.0)
    assert lm.radius == pytest.approx(0.125) and lm.rejected == 2
    for _ in range(10):
        lm.update(0.9, lm.radius, ok=True)
    assert lm.radius == _LevenbergMarquardt.MAX_RADIUS and lm.rejected == 0


def test_step_stays_inside_the_bounds_and_holds_a_coordinate_pushed_outwards():
    jac, r = _problem()
    g = jac.T @ r
    theta = np.array([0.0, 0.3, -0.2])
    # Coordinate 0 sits at a bound that its descent direction (-g) points through.
    lower = np.array([0.0 if g[0] > 0 else -np.inf, -0.5, -0.25])
    upper = np.array([np.inf if g[0] > 0 else 0.0, 0.35, 0.1])
    lm = _LevenbergMarquardt()
    step, predicted = lm.step(jac, r, theta, (lower, upper))
    assert step[0] == 0.0
    assert np.all(theta + step >= lower) and np.all(theta + step <= upper)
    assert predicted > 0
