"""Motion-capture data of static poses: :class:`MocapDataset`, and static frames of a time series.

A dataset holds, per static frame: the controls (one per tendon: pull-in in m, or tension in N),
an optional payload mass (kg) hanging at one site, an optional external force (N) at one site
(world-fixed or follower), and marker positions (m) in the motion-capture frame, with NaN for a
marker the system did not see in that frame (the frame is kept; that marker is masked), and
optional marker orientations (rotation matrices, e.g. of a rigid body at the tip).

Arrays are numpy (data, not traced parameters). Files: :mod:`pacjax.io.mocapfile` (the documented
CSV format and the OptiTrack Motive importer).
"""

from __future__ import annotations

import warnings

import equinox as eqx
import numpy as np

#: Marker coordinates larger than this (m) are taken as a units mistake (millimetres).
MAX_COORDINATE = 20.0
#: Payloads heavier than this (kg) are taken as a units mistake (grams).
MAX_PAYLOAD = 100.0


def check_site(owner: str, site) -> tuple[int, float, tuple[float, float, float]]:
    """A marker or load site as ``(segment, s, (ox, oy, oz))``; raise naming ``owner``."""
    if not isinstance(site, (tuple, list)) or len(site) not in (2, 3):
        raise ValueError(f"{owner} must be (segment, s) or (segment, s, offset_xyz), got {site!r}")
    seg, s = site[0], site[1]
    if isinstance(seg, float) and float(seg).is_integer():
        seg = int(seg)
    if not isinstance(seg, (int, np.integer)) or isinstance(seg, bool) or seg < 0:
        raise ValueError(f"{owner}: segment must be an integer >= 0, got {seg!r}")
    try:
        s = float(s)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}: s must be a number in [0, 1], got {s!r}") from None
    if not (np.isfinite(s) and 0.0 <= s <= 1.0):
        raise ValueError(f"{owner}: s must lie in [0, 1], got {s}")
    offset = (0.0, 0.0, 0.0)
    if len(site) == 3:
        offset = tuple(float(v) for v in np.asarray(site[2], float).reshape(-1))
        if len(offset) != 3 or not np.all(np.isfinite(offset)):
            raise ValueError(f"{owner}: offset must be 3 finite numbers (m), got {site[2]!r}")
    return int(seg), s, offset


def _array(name: str, x, shape: tuple, allow_nan: bool = False) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numeric, got {type(x).__name__}") from None
    if a.ndim != len(shape) or any(
        w is not None and w != n for w, n in zip(shape, a.shape, strict=True)
    ):
        want = "(" + ", ".join("any" if w is None else str(w) for w in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {a.shape}")
    bad = np.isinf(a) if allow_nan else ~np.isfinite(a)
    if np.any(bad):
        raise ValueError(f"{name} contains {'infinite' if allow_nan else 'NaN or infinite'} values")
    return a


def _base_rotations(value, n_frames: int) -> np.ndarray:
    """(frames, 3, 3) proper rotations, or a ValueError naming ``base_rotation``."""
    r = _array("base_rotation", value, (n_frames, 3, 3))
    eye = np.broadcast_to(np.eye(3), r.shape)
    bad = ~np.all(np.isclose(np.swapaxes(r, -1, -2) @ r, eye, atol=1e-6), axis=(1, 2))
    bad |= np.linalg.det(r) < 0
    if bad.any():
        raise ValueError(
            f"base_rotation[{int(np.flatnonzero(bad)[0])}] is not a proper rotation matrix "
            "(R^T R = I, det 1)"
        )
    return r


def _gravity_directions(value, n_frames: int) -> np.ndarray:
    """(frames, 3) unit vectors, or a ValueError naming ``gravity_direction``."""
    g = _array("gravity_direction", value, (n_frames, 3))
    bad = np.abs(np.linalg.norm(g, axis=1) - 1.0) > 1e-6
    if bad.any():
        raise ValueError(
            f"gravity_direction[{int(np.flatnonzero(bad)[0])}] is not a unit vector "
            f"(norm {np.linalg.norm(g[bad][0]):.6g})"
        )
    return g


def _frame_values(value, n_frames: int) -> dict:
    """``{name: (frames, ...) array}``, or a ValueError naming the entry."""
    if not isinstance(value, dict) or not value:
        raise ValueError("frame_values must be a non-empty dict of name -> (frames, ...) array")
    out = {}
    for name, x in value.items():
        a = _array(f"frame_values[{name!r}]", x, (n_frames,) + (None,) * (np.ndim(x) - 1))
        if a.ndim == 0:
            raise ValueError(f"frame_values[{name!r}] must have a leading frame axis")
        out[str(name)] = a
    return out


def _holdout_mask(value, n_frames: int) -> np.ndarray:
    """(frames,) bool from 0/1 or booleans, or a ValueError naming ``holdout``."""
    a = _array("holdout", value, (n_frames,))
    if not np.all((a == 0) | (a == 1)):
        raise ValueError("holdout must be 0 or 1 (or False/True) in every frame")
    return a.astype(bool)


class MocapDataset(eqx.Module):
    """Static frames of a motion-capture session (build with :meth:`from_arrays`).

    Attributes:
        controls: (frames, n_tendons) pull-in (m) or tension (N) per tendon.
        markers: (frames, m, 3) marker positions (m) in the motion-capture frame; NaN = missing.
        sites: ``((segment, s, offset_xyz), ...)``, one per marker: where it sits on the robot
            (offset in the local cross-section frame, m: the marker's stand-off).
        payload_mass: (frames,) kg hanging at ``payload_site``, or None.
        payload_site: ``(segment, s)`` of the payload; None: the tip.
        force: (frames, 3) N at ``force_site``, or None.
        force_site: ``(segment, s)`` of the force; None: the tip.
        force_follower: the force is in the local cross-section frame (turns with the body).
        orientations: (frames, m, 3, 3) measured rotations (mocap frame) at the sites, NaN where
            missing, or None.
        time: (frames,) s, or None.
        base_rotation: (frames, 3, 3) the robot's base orientation (base frame -> world) in
            each frame, for data taken with the base turned from frame to frame (the scene's
            own ``Robot.base_rotation`` is then replaced), or None.
        gravity_direction: (frames, 3) unit vector of gravity (world frame) in each frame (the
            scene's :class:`pacjax.Gravity` direction is then replaced), or None.
        frame_values: ``{name: (frames, ...) array}`` of any other per-frame quantity, put
            into the scene by the ``frame_update`` hook of :func:`pacjax.identify` (and
            :func:`pacjax.synthetic_mocap`), or None.
        holdout: (frames,) True for a frame to hold out of a fit (the CSV's ``holdout``
            column), or None.
    """

    controls: np.ndarray
    markers: np.ndarray
    sites: tuple = eqx.field(static=True)
    payload_mass: np.ndarray | None = None
    payload_site: tuple | None = eqx.field(static=True, default=None)
    force: np.ndarray | None = None
    force_site: tuple | None = eqx.field(static=True, default=None)
    force_follower: bool = eqx.field(static=True, default=False)
    orientations: np.ndarray | None = None
    time: np.ndarray | None = None
    base_rotation: np.ndarray | None = None
    gravity_direction: np.ndarray | None = None
    frame_values: dict | None = None
    holdout: np.ndarray | None = None

    @classmethod
    def from_arrays(
        cls,
        controls,
        markers,
        sites,
        payload_mass=None,
        *,
        payload_site=None,
        force=None,
        force_site=None,
        force_follower: bool = False,
        orientations=None,
        time=None,
        base_rotation=None,
        gravity_direction=None,
        frame_values=None,
        holdout=None,
    ) -> MocapDataset:
        """Validate and wrap arrays (SI units: m, kg, N; see the class attributes).

        Raises a ValueError naming the field for wrong shapes, infinite or NaN values where they
        are not allowed, coordinates that look like millimetres, a marker never observed, or a
        frame in which no marker is observed.
        """
        markers = _markers_array(markers)
        n_frames, n_markers = markers.shape[:2]
        controls = np.asarray(controls, dtype=float)
        if controls.ndim == 1 and n_frames == 1:
            controls = controls[None]
        controls = _array("controls", controls, (n_frames, None))
        sites = _marker_sites(sites, n_markers)
        _check_observed(markers, sites)
        payload_mass, payload_site = _payload(payload_mass, payload_site, n_frames)
        force, force_site = _force(force, force_site, n_frames)
        if orientations is not None:
            orientations = _orientations(orientations, n_frames, n_markers)
        if time is not None:
            time = _array("time", time, (n_frames,))
        if base_rotation is not None:
            base_rotation = _base_rotations(base_rotation, n_frames)
        if gravity_direction is not None:
            gravity_direction = _gravity_directions(gravity_direction, n_frames)
        if frame_values is not None:
            frame_values = _frame_values(frame_values, n_frames)
        if holdout is not None:
            holdout = _holdout_mask(holdout, n_frames)
        return cls(
            controls=controls,
            markers=markers,
            sites=sites,
            payload_mass=payload_mass,
            payload_site=payload_site,
            force=force,
            force_site=force_site,
            force_follower=bool(force_follower),
            orientations=orientations,
            time=time,
            base_rotation=base_rotation,
            gravity_direction=gravity_direction,
            frame_values=frame_values,
            holdout=holdout,
        )

    # ------------------------------------------------------------------------- structure
    @property
    def n_frames(self) -> int:
        return self.markers.shape[0]

    @property
    def n_markers(self) -> int:
        return self.markers.shape[1]

    @property
    def n_controls(self) -> int:
        return self.controls.shape[1]

    @property
    def observed(self) -> np.ndarray:
        """(frames, m) True where the marker was seen."""
        return np.isfinite(self.markers).all(-1)

    def __len__(self) -> int:
        return self.n_frames

    def __getitem__(self, index) -> MocapDataset:
        """Frames ``index`` (a slice, an integer array, a boolean mask, or one integer)."""
        if isinstance(index, (int, np.integer)):
            index = slice(int(index), int(index) + 1 if index != -1 else None)
        if isinstance(index, np.ndarray) and index.dtype == bool and index.shape != (len(self),):
            raise IndexError(f"boolean index must have shape ({len(self)},), got {index.shape}")

        def pick(x):
            return None if x is None else x[index]

        out = MocapDataset(
            controls=self.controls[index],
            markers=self.markers[index],
            sites=self.sites,
            payload_mass=pick(self.payload_mass),
            payload_site=self.payload_site,
            force=pick(self.force),
            force_site=self.force_site,
            force_follower=self.force_follower,
            orientations=pick(self.orientations),
            time=pick(self.time),
            base_rotation=pick(self.base_rotation),
            gravity_direction=pick(self.gravity_direction),
            frame_values=(
                None
                if self.frame_values is None
                else {k: v[index] for k, v in self.frame_values.items()}
            ),
            holdout=pick(self.holdout),
        )
        if out.n_frames == 0:
            raise IndexError(f"selection {index!r} holds no frames")
        return out

    def split(self, holdout, seed: int = 0) -> tuple[MocapDataset, MocapDataset]:
        """``(train, held-out)``: a random fraction ``holdout`` of the frames held out, or the
        frames whose (0-based) indices ``holdout`` lists."""
        if np.iterable(holdout) and not isinstance(holdout, (str, bytes)):
            return self._split_frames(holdout)
        if not 0.0 < holdout < 1.0:
            raise ValueError(f"holdout must be a fraction in (0, 1), got {holdout}")
        n_test = int(round(holdout * self.n_frames))
        if n_test < 1 or n_test >= self.n_frames:
            raise ValueError(
                f"holdout={holdout} of {self.n_frames} frames leaves no train or no test frame"
            )
        order = np.random.default_rng(seed).permutation(self.n_frames)
        return self[np.sort(order[n_test:])], self[np.sort(order[:n_test])]

    def _split_frames(self, frames) -> tuple[MocapDataset, MocapDataset]:
        index = np.asarray(list(frames))
        if index.size == 0 or not np.issubdtype(index.dtype, np.integer):
            raise ValueError(f"holdout frames must be frame indices (integers), got {frames!r}")
        bad = index[(index < 0) | (index >= self.n_frames)]
        if bad.size:
            raise ValueError(
                f"holdout frame {int(bad[0])} does not exist (the data have {self.n_frames} "
                f"frames, 0..{self.n_frames - 1})"
            )
        held = np.zeros(self.n_frames, bool)
        held[index] = True
        if held.all():
            raise ValueError("holdout holds out every frame: none is left to fit")
        return self[np.flatnonzero(~held)], self[np.flatnonzero(held)]

    def conditions(self) -> np.ndarray:
        """(frames, k) the inputs of each frame: controls, payload, force, base and gravity
        directions, frame values."""
        cols = [self.controls]
        if self.payload_mass is not None:
            cols.append(self.payload_mass[:, None])
        if self.force is not None:
            cols.append(self.force)
        if self.base_rotation is not None:
            cols.append(self.base_rotation.reshape(self.n_frames, 9))
        if self.gravity_direction is not None:
            cols.append(self.gravity_direction)
        for value in (self.frame_values or {}).values():
            cols.append(value.reshape(self.n_frames, -1))
        return np.concatenate(cols, axis=1)

    @classmethod
    def from_time_series(
        cls,
        time,
        controls,
        markers,
        sites,
        *,
        window: float = 0.5,
        tolerance: float = 5e-4,
        payload_mass=None,
        orientations=None,
        **kwargs,
    ) -> MocapDataset:
        """Static frames of a recording: one averaged frame per settled plateau.

        See :func:`static_frames` for the settle criterion. ``controls`` (samples, n_tendons)
        and ``payload_mass`` (samples,) are sampled at the same times as ``markers`` (samples,
        m, 3, m); the controls are the ones held over the plateau. Further keyword arguments go
        to :meth:`from_arrays`.
        """
        time = _array("time", time, (None,))
        markers = np.asarray(markers, dtype=float)
        if markers.ndim != 3 or markers.shape[0] != time.shape[0] or markers.shape[2] != 3:
            raise ValueError(
                f"markers must have shape ({time.shape[0]}, m, 3) like time, got {markers.shape}"
            )
        controls = _array("controls", controls, (time.shape[0], None))
        if payload_mass is not None:
            payload_mass = _array("payload_mass", payload_mass, (time.shape[0],))
        inputs = controls if payload_mass is None else np.c_[controls, payload_mass]
        plateaus = static_frames(time, markers, inputs, window=window, tolerance=tolerance)
        if not plateaus:
            raise ValueError(
                f"no static frame: no stretch of {window} s in which the inputs are constant and "
                f"every marker stays within {1e3 * tolerance:.2g} mm (raise tolerance= or "
                "lower window=)"
            )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a marker unseen over a window
            mean = np.stack([np.nanmean(markers[idx], axis=0) for idx in plateaus])
            ori = None
            if orientations is not None:
                ori = np.stack([_mean_rotation(orientations[idx]) for idx in plateaus])
        last = np.array([idx[-1] for idx in plateaus])
        return cls.from_arrays(
            controls[last],
            mean,
            sites,
            None if payload_mass is None else payload_mass[last],
            orientations=ori,
            time=time[last],
            **kwargs,
        )


def _markers_array(markers) -> np.ndarray:
    """``markers`` as a checked (frames, m, 3) float array (NaN allowed, at least one frame)."""
    markers = np.asarray(markers, dtype=float) if markers is not None else None
    if markers is None or markers.ndim != 3 or markers.shape[-1] != 3:
        shape = None if markers is None else markers.shape
        raise ValueError(f"markers must have shape (frames, m, 3), got {shape}")
    n_frames, n_markers = markers.shape[:2]
    if n_frames == 0:
        raise ValueError("markers has no frames")
    return _array("markers", markers, (n_frames, n_markers, 3), allow_nan=True)


def _marker_sites(sites, n_markers: int) -> tuple:
    """One checked ``(segment, s, offset)`` per marker."""
    if not isinstance(sites, (tuple, list)) or len(sites) != n_markers:
        raise ValueError(
            f"sites must list one (segment, s) per marker ({n_markers}), got "
            f"{len(sites) if isinstance(sites, (tuple, list)) else sites!r}"
        )
    return tuple(check_site(f"sites[{j}]", x) for j, x in enumerate(sites))


def _check_observed(markers: np.ndarray, sites: tuple) -> None:
    """Raise for a partly NaN marker, a marker or a frame never observed, or millimetres."""
    # NaN is "missing": the whole frame's partial observation is kept and masked.
    seen = np.isfinite(markers).all(-1)
    partial = np.isfinite(markers).any(-1) & ~seen
    if np.any(partial):
        f, j = np.argwhere(partial)[0]
        raise ValueError(
            f"markers[{f}, {j}] is partly NaN ({markers[f, j]}): a missing marker must be NaN "
            "in all three coordinates"
        )
    if not seen.any():
        raise ValueError("markers: every marker position is NaN (nothing was observed)")
    never = np.flatnonzero(~seen.any(0))
    if never.size:
        raise ValueError(
            f"markers: marker(s) {never.tolist()} (sites {[sites[j][:2] for j in never]}) are "
            "NaN in every frame; drop them from the dataset"
        )
    empty = np.flatnonzero(~seen.any(1))
    if empty.size:
        raise ValueError(
            f"markers: frame(s) {empty[:10].tolist()} observe no marker at all; drop them"
        )
    biggest = np.nanmax(np.abs(markers))
    if biggest > MAX_COORDINATE:
        raise ValueError(
            f"markers reach {biggest:.4g}: marker positions must be in metres (this looks "
            "like millimetres; divide by 1000)"
        )


def _payload(payload_mass, payload_site, n_frames: int) -> tuple[np.ndarray | None, tuple | None]:
    """The checked (frames,) payload masses (a scalar: the same in every frame) and site."""
    if payload_mass is None:
        if payload_site is not None:
            raise ValueError("payload_site given without payload_mass")
        return None, None
    payload_mass = np.asarray(payload_mass, dtype=float)
    if payload_mass.ndim == 0:
        payload_mass = np.full(n_frames, float(payload_mass))
    payload_mass = _array("payload_mass", payload_mass, (n_frames,))
    if np.any(payload_mass < 0):
        raise ValueError("payload_mass must be >= 0 (kg)")
    if np.any(payload_mass > MAX_PAYLOAD):
        raise ValueError(f"payload_mass exceeds {MAX_PAYLOAD:g}: it must be in kg (not g)")
    return payload_mass, check_site("payload_site", payload_site)[:2] if payload_site else None


def _force(force, force_site, n_frames: int) -> tuple[np.ndarray | None, tuple | None]:
    """The checked (frames, 3) forces (one (3,) force: the same in every frame) and site."""
    if force is None:
        if force_site is not None:
            raise ValueError("force_site given without force")
        return None, None
    force = np.asarray(force, dtype=float)
    if force.shape == (3,):
        force = np.broadcast_to(force, (n_frames, 3)).copy()
    force = _array("force", force, (n_frames, 3))
    return force, check_site("force_site", force_site)[:2] if force_site else None


def _orientations(orientations, n_frames: int, n_markers: int) -> np.ndarray:
    """The checked (frames, m, 3, 3) rotations, NaN (all 9 entries) where missing."""
    orientations = _array("orientations", orientations, (n_frames, n_markers, 3, 3), allow_nan=True)
    flat = orientations.reshape(n_frames, n_markers, 9)
    if np.any(np.isfinite(flat).any(-1) & ~np.isfinite(flat).all(-1)):
        raise ValueError("orientations: a missing rotation must be NaN in all 9 entries")
    ok = np.isfinite(flat).all(-1)
    if not ok.any():
        raise ValueError("orientations are NaN everywhere; pass orientations=None")
    r = orientations[ok]
    err = np.abs(np.einsum("kji,kjl->kil", r, r) - np.eye(3)).max()
    if err > 1e-3 or np.any(np.linalg.det(r) < 0):
        raise ValueError("orientations must be rotation matrices (R^T R = I, det 1)")
    return orientations


def _mean_rotation(r: np.ndarray) -> np.ndarray:
    """Chordal mean of rotations (k, m, 3, 3) over k, NaN where none was seen."""
    out = np.full(r.shape[1:], np.nan)
    for j in range(r.shape[1]):
        ok = np.isfinite(r[:, j].reshape(len(r), 9)).all(-1)
        if ok.any():
            u, _, vt = np.linalg.svd(r[ok, j].mean(0))
            d = np.sign(np.linalg.det(u @ vt))
            out[j] = u @ np.diag([1.0, 1.0, d]) @ vt
    return out


def static_frames(
    time, markers, inputs=None, *, window: float = 0.5, tolerance: float = 5e-4
) -> list[np.ndarray]:
    """Plateaus of a recording in which the robot has settled.

    Sample ``i`` is *settled* when, over the samples in ``[t_i - window, t_i]``, the inputs
    (controls, payload) do not change and every marker observed there stays within
    ``tolerance`` (m) of its mean in every coordinate, with at least one marker observed. Each
    maximal run of settled samples is one static pose; its frame is the last ``window``
    seconds of the run (returned as sample indices, to be averaged).

    Args:
        time: (samples,) seconds, increasing.
        markers: (samples, m, 3) m, NaN = missing.
        inputs: optional (samples, k) commands that must be constant.
        window: settle time (s).
        tolerance: largest deviation (m) from the window's mean.
    """
    time = np.asarray(time, dtype=float)
    markers = np.asarray(markers, dtype=float)
    if time.ndim != 1 or len(time) < 2 or np.any(np.diff(time) <= 0):
        raise ValueError("time must be a 1-D increasing array of at least 2 samples")
    if markers.shape[:1] != time.shape or markers.ndim != 3:
        raise ValueError(f"markers must have shape ({len(time)}, m, 3), got {markers.shape}")
    if not window > 0 or not tolerance > 0:
        raise ValueError("window and tolerance must be > 0")
    n = len(time)
    start = np.searchsorted(time, time - window, side="left")
    full = time - time[0] >= window
    settled = np.zeros(n, bool)
    flat = markers.reshape(n, -1)
    inp = None if inputs is None else np.asarray(inputs, float).reshape(n, -1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for i in np.flatnonzero(full):
            w = slice(start[i], i + 1)
            if inp is not None and np.any(inp[w] != inp[i]):
                continue
            block = flat[w]
            if not np.isfinite(block).any():
                continue
            spread = np.nanmax(np.abs(block - np.nanmean(block, axis=0)))
            settled[i] = spread <= tolerance
    runs, i = [], 0
    while i < n:
        if not settled[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and settled[j + 1]:
            j += 1
        runs.append(np.arange(start[j], j + 1))
        i = j + 1
    return runs
