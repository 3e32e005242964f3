"""Marker sites: where a marker sits on the robot, ``(segment, s)`` with an optional local
offset, checked once when a scene, a dataset or a query names them."""

import numpy as np

Site = tuple  # (segment, s) or (segment, s, (ox, oy, oz))


def normalise_sites(sites, n_segments: int, owner: str = "sites") -> tuple:
    """Validate marker sites and return them as ``((segment, s, (ox, oy, oz)), ...)``."""
    if isinstance(sites, (str, bytes)) or not np.iterable(sites):
        raise TypeError(f"{owner} must be a sequence of (segment, s) sites, got {sites!r}")
    out = []
    for i, site in enumerate(sites):
        if not isinstance(site, (tuple, list)) or len(site) not in (2, 3):
            raise ValueError(
                f"{owner}[{i}] must be (segment, s) or (segment, s, offset_xyz), got {site!r}"
            )
        seg, s = site[0], site[1]
        if (
            not isinstance(seg, (int, np.integer))
            or isinstance(seg, (bool, np.bool_))
            or not 0 <= seg < n_segments
        ):
            raise ValueError(
                f"{owner}[{i}]: segment {seg!r} does not exist (robot has {n_segments})"
            )
        if not _is_real(s) or not (np.isfinite(s) and 0.0 <= s <= 1.0):
            raise ValueError(f"{owner}[{i}]: s must lie in [0, 1], got {s!r}")
        offset = site[2] if len(site) == 3 else (0.0, 0.0, 0.0)
        if (
            not np.iterable(offset)
            or len(offset) != 3
            or not all(_is_real(v) for v in offset)
            or not np.all(np.isfinite(np.asarray(offset, float)))
        ):
            raise ValueError(f"{owner}[{i}]: offset must be 3 finite numbers, got {offset!r}")
        offset = tuple(float(v) for v in offset)
        out.append((int(seg), float(s), offset))
    return tuple(out)


def _is_real(x) -> bool:
    """A plain real number (Python or numpy scalar, or a 0-d array), not a bool or a string."""
    if isinstance(x, (bool, np.bool_)) or np.ndim(x) != 0:
        return False
    return np.issubdtype(np.asarray(x).dtype, np.floating) or np.issubdtype(
        np.asarray(x).dtype, np.integer
    )
