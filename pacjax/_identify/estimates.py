"""Estimates and their uncertainty at the optimum of a fit: the Laplace / Gauss-Newton
covariance of the internal coordinates, and the report's table of fitted values in physical
units with their standard deviations, bounds held and identifiability."""

import jax.numpy as jnp
import numpy as np

from .problem import PARAMETERS, STEP_SCALE, Problem

#: A direction of the internal coordinates whose singular value, with every Jacobian column
#: scaled to unit norm, is below this fraction of the largest moves the markers too little for
#: the data to pin it down: its coordinates are "not identified", never given std 0.
UNIDENTIFIED_RTOL = 1e-7


def covariance(current, n_obs: int, n_theta: int) -> tuple[np.ndarray, np.ndarray]:
    """Laplace / Gauss-Newton covariance ``s^2 (J^T J)^-1`` of the internal coordinates at the
    optimum, and their standard deviations.

    Columns are scaled to unit norm first (units must not decide the rank). Coordinates that
    take part in a direction the data do not see (a zero column: a parameter with no effect;
    or a combination, e.g. stiffness and density shrinking together) get an infinite standard
    deviation and NaN covariances; the rest come from the pseudo-inverse on the seen subspace.
    """
    r, jac = current.stacked()
    dof = max(n_obs - n_theta, 1)
    s2 = float(r @ r) / dof
    norms = np.linalg.norm(jac, axis=0)
    safe = np.where(norms > 0, norms, 1.0)
    scaled = jac / safe
    _, sv, vt = np.linalg.svd(scaled, full_matrices=True)
    sv = np.concatenate([sv, np.zeros(n_theta - sv.size)])
    blind = sv <= UNIDENTIFIED_RTOL * max(sv.max(initial=0.0), np.finfo(float).tiny)
    unseen = (norms == 0) | np.any(np.abs(vt[blind]) > 0.1, axis=0)
    seen_sv = np.where(blind, np.inf, sv)
    cov_scaled = (vt.T / seen_sv**2) @ vt
    cov = s2 * cov_scaled / np.outer(safe, safe)
    cov[unseen, :] = np.nan
    cov[:, unseen] = np.nan
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    std[unseen] = np.inf
    return cov, std


def parameter_table(
    problem: Problem, labels, bounds, translation0, theta, std_theta, trans
) -> tuple[dict, list, list]:
    """The report's entry of every block, the coordinate names and which are identifiable.

    ``labels``: per block, the labels of its reported values; ``bounds``: (lower, upper) of the
    internal coordinates; ``translation0``: the starting mocap translation (m); ``trans`` the
    fitted one."""
    parameters, names, identifiable = {}, [], []
    k = 0
    for block, init, label, th in zip(
        problem.blocks, problem.initial, labels, problem.split(theta), strict=True
    ):
        sd = std_theta[k : k + block.size]
        lower, upper = (b[k : k + block.size] for b in bounds)
        k += block.size
        value, start, std = _block_estimate(problem, translation0, block, init, th, sd, trans)
        if len(label) == 1 and value.size > 1:  # one shared factor on equal values
            value, start, std = value[:1], start[:1], std[:1]
        entry = _parameter_entry(block, label, start, value, std)
        # Which values the bounds hold (relative to the bound's size: log coordinates).
        th = np.asarray(th)
        near = 1e-9 * np.maximum(1.0, np.abs(th))
        flags = np.where(th <= lower + near, "lower", np.where(th >= upper - near, "upper", ""))
        if flags.size == len(label):
            entry["at_bound"] = [f or None for f in flags.tolist()]
        else:  # one shared factor
            entry["at_bound"] = [flags[0] or None] * len(label)
        parameters[block.name] = entry
        names += _coordinate_names(block, label)
        # A log-coordinate with a standard deviation above 1 is not pinned down by the data;
        # an infinite one is not seen by them at all (covariance).
        identifiable += [bool(s < 1.0) if block.log else bool(np.isfinite(s)) for s in sd]
    return parameters, names, identifiable


def _block_estimate(problem: Problem, translation0, block, init, th, sd, trans):
    """A block's fitted and starting values and their standard deviations (physical units),
    from its internal coordinates ``th`` and their standard deviations ``sd``."""
    if block.name == "mocap_transform":
        value = np.concatenate([np.asarray(th[:3]), np.asarray(trans)])
        start = np.concatenate([np.zeros(3), translation0])
        return value, start, sd
    value = np.asarray(problem.physical(block, init, jnp.asarray(th)), float).reshape(-1)
    start = np.asarray(init, float).reshape(-1)
    scale = value if block.log else np.full(value.shape, STEP_SCALE.get(block.name, 1.0))
    return value, start, np.abs(scale) * (sd if block.size == value.size else sd[0])


def _parameter_entry(block, label, start, value, std) -> dict:
    rel = [
        float(s / abs(v)) if v != 0 and np.isfinite(s) else None
        for s, v in zip(std, value, strict=True)
    ]
    return {
        "unit": PARAMETERS[block.name][1],
        "labels": list(label),
        "initial": [float(v) for v in start],
        "value": [float(v) for v in value],
        "std": [float(v) if np.isfinite(v) else None for v in std],
        "relative_std": rel,
    }


def _coordinate_names(block, label) -> list[str]:
    """Names of a block's internal coordinates."""
    if block.size == len(label):
        return [f"{block.name}{x}" for x in label]
    return [block.name] if block.size == 1 else [f"{block.name}[{i}]" for i in range(block.size)]
