"""The small scenes shared by the dynamics tests (``test_dynamics*.py``)."""

import jax.numpy as jnp
import numpy as np

import pacjax as pj

HANGING = np.diag([1.0, -1.0, -1.0])


def small_scene(density=0.3, order=1, quadrature_points=4):
    """One segment, linear polynomial curvature, 4 Gauss points, gravity, an end mass and two
    length-mode tendons: the structure the default dynamics tests share (one compilation).
    ``order=0, quadrature_points=2``: the smallest scene with all of these forces."""
    segment = pj.Segment(0.15, 0.02, 600.0, linear_density=density, radius=0.012)
    guides = (0.0, 0.5, 1.0)
    tendons = (
        pj.Tendon(0, 0.0, 0.01, gain=2.0e3, guides=guides),
        pj.Tendon(0, 2.1, 0.01, gain=2.0e3, guides=guides),
    )
    loads = (pj.Gravity(), pj.PointMass(0.03, 0, 1.0))
    return pj.Scene(
        pj.Robot([segment], base_rotation=HANGING),
        pj.PolynomialCurvature(order=order),
        tendons=tendons,
        loads=loads,
        quadrature_points=quadrature_points,
    )


SCENE = small_scene()
CONTROLS = jnp.array([0.008, 0.002])


def cantilever(model, n_segments, ei=0.05, density=0.4, length=0.3):
    """A uniform cantilever without loads: ``(scene, EI, rho A, length)``."""
    segments = [pj.Segment(length / n_segments, ei, 1e5, linear_density=density)] * n_segments
    return pj.Scene(pj.Robot(segments), model), ei, density, length


def free_scene():
    """No tendons, no damping: a conservative pendulum-like body (gravity and elasticity)."""
    segment = pj.Segment(0.15, 0.02, 600.0, linear_density=0.3, radius=0.012)
    return pj.Scene(
        pj.Robot([segment]),
        pj.PolynomialCurvature(order=1),
        loads=(pj.Gravity(),),
        quadrature_points=4,
    )
