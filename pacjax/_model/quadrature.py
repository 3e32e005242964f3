"""Gauss-Legendre rules on [0, 1]."""

import functools

import numpy as np


@functools.cache
def gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of the ``n``-point Gauss-Legendre rule on ``[0, 1]``.

    Exact for polynomials of degree ``2 n - 1``. Returned as float64 numpy arrays, so they are
    compile-time constants inside a trace.
    """
    if n < 1:
        raise ValueError(f"a quadrature rule needs at least 1 point, got {n}")
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w
