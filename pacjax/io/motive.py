"""OptiTrack Motive CSV exports: read a take, pick its static frames, attach the commands.

:func:`read_motive_csv` reads Motive's CSV export (format 1.2x): a metadata line (``Format
Version``, ``Length Units``, ``Rotation Type``, ...), a blank line, the ``Type`` / ``Name`` /
``ID`` rows, a row naming each column group (``Rotation``, ``Position``, ``Mean Marker Error``,
``Marker Quality``) and the ``Frame, Time (Seconds), X, Y, Z, ...`` row, then one row per
captured frame. Rigid bodies give a position and a quaternion, markers (``Marker``, ``Rigid Body
Marker``) a position; lengths are converted to metres. Pick static frames and attach controls
with :meth:`pacjax.MocapDataset.from_time_series` (see :func:`motive_dataset`).
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass, field

import numpy as np

from .._identify.dataset import MocapDataset
from .mocapfile import number_cell, quaternion_to_matrix

__all__ = ["read_motive_csv", "motive_dataset", "MotiveTake"]

_MOTIVE_UNITS = {"meters": 1.0, "millimeters": 1e-3, "centimeters": 1e-2}


@dataclass
class MotiveTake:
    """The tracks of one Motive take, in metres and seconds.

    Attributes:
        time: (samples,) s.
        frame: (samples,) Motive frame numbers.
        markers: name -> (samples, 3) positions (m), NaN where not tracked.
        rigid_bodies: name -> (positions (samples, 3) m, rotations (samples, 3, 3)).
        metadata: the first line's key/value pairs (``Capture Frame Rate``, ...).
    """

    time: np.ndarray
    frame: np.ndarray
    markers: dict = field(default_factory=dict)
    rigid_bodies: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)

    def positions(self, names) -> np.ndarray:
        """(samples, len(names), 3): markers, or rigid bodies' positions, by name."""
        out = []
        for name in names:
            if name in self.markers:
                out.append(self.markers[name])
            elif name in self.rigid_bodies:
                out.append(self.rigid_bodies[name][0])
            else:
                known = sorted(self.markers) + sorted(self.rigid_bodies)
                raise ValueError(f"no marker or rigid body named {name!r} in the take ({known})")
        return np.stack(out, 1)


def read_motive_csv(path, length_unit: str | None = None) -> MotiveTake:
    """Read an OptiTrack Motive CSV export (see the module docstring).

    Args:
        path: the file.
        length_unit: ``"meters"``, ``"millimeters"`` or ``"centimeters"`` when the export's
            header does not say (``Length Units``); overrides nothing the header states.
    """
    path = os.fspath(path)
    with open(path, encoding="utf-8-sig", newline="") as f:
        rows = list(csv.reader(f))
    metadata = _motive_metadata(path, rows)
    type_row = rows[_find_motive_row(path, rows, "Type", 1)]
    name_row = rows[_find_motive_row(path, rows, "Name", 1)]
    head = _find_motive_row(path, rows, "Frame", 0)
    group_row, axis_row = rows[head - 1], rows[head]
    scale = _motive_scale(path, metadata.get("Length Units", length_unit))
    rotation_type = metadata.get("Rotation Type", "Quaternion")
    table = _motive_table(path, rows[head + 1 :], len(axis_row))
    groups = _motive_groups(type_row, name_row, group_row, axis_row)
    markers, bodies = _motive_tracks(path, groups, table, scale, rotation_type)
    return MotiveTake(
        time=table[:, 1], frame=table[:, 0], markers=markers, rigid_bodies=bodies, metadata=metadata
    )


def _motive_metadata(path: str, rows: list[list[str]]) -> dict:
    """The first line's ``key, value, key, value, ...`` cells, after checking that it is one."""
    if not rows or not rows[0] or rows[0][0].strip() != "Format Version":
        raise ValueError(f"{path}: not a Motive CSV export (first cell must be 'Format Version')")
    cells = [c.strip() for c in rows[0]]
    return {cells[k]: cells[k + 1] for k in range(0, len(cells) - 1, 2)}


def _find_motive_row(path: str, rows: list[list[str]], label: str, column: int) -> int:
    """Index of the header row whose cell ``column`` is ``label`` (among the first 12 rows)."""
    for k, r in enumerate(rows[:12]):
        if len(r) > column and r[column].strip() == label:
            return k
    raise ValueError(f"{path}: Motive header row {label!r} not found")


def _motive_scale(path: str, unit: str | None) -> float:
    """Metres per ``Length Units`` (the header's, else the caller's)."""
    if unit is None:
        raise ValueError(f"{path}: the export does not state its Length Units; pass length_unit=")
    if unit.lower() not in _MOTIVE_UNITS:
        raise ValueError(f"{path}: unknown Length Units {unit!r} (known: {list(_MOTIVE_UNITS)})")
    return _MOTIVE_UNITS[unit.lower()]


def _motive_table(path: str, rows: list[list[str]], width: int) -> np.ndarray:
    """(samples, width) numbers of the data rows (blank rows dropped, short rows and empty cells
    NaN); column 0 is the frame, column 1 the time, which must be complete."""
    data = [r for r in rows if any(c.strip() for c in r)]
    if not data:
        raise ValueError(f"{path}: no data rows")
    table = np.full((len(data), width), np.nan)
    for k, r in enumerate(data):
        for c in range(min(width, len(r))):
            table[k, c] = number_cell(r[c], f"{path}, data row {k}, column {c}")
    if np.any(~np.isfinite(table[:, 1])):
        raise ValueError(f"{path}: the time column has empty cells")
    return table


def _motive_groups(type_row, name_row, group_row, axis_row) -> dict:
    """``{(type, name, group): {axis: column}}`` for the columns after frame and time (header
    rows may be shorter than the axis row: their missing cells count as empty)."""
    groups: dict[tuple[str, str, str], dict[str, int]] = {}
    for c in range(2, len(axis_row)):
        kind = type_row[c].strip() if c < len(type_row) else ""
        name = name_row[c].strip() if c < len(name_row) else ""
        group = group_row[c].strip() if c < len(group_row) else ""
        groups.setdefault((kind, name, group), {})[axis_row[c].strip()] = c
    return groups


def _motive_tracks(path: str, groups: dict, table: np.ndarray, scale: float, rotation_type: str):
    """``(markers, rigid bodies)`` by name: positions in metres; a rigid body's rotations with
    them."""
    markers, bodies = {}, {}
    for (kind, name, group), axes in groups.items():
        if group != "Position":
            continue
        if not all(a in axes for a in "XYZ"):
            raise ValueError(f"{path}: {kind} {name!r} position lacks X, Y or Z columns")
        pos = table[:, [axes["X"], axes["Y"], axes["Z"]]] * scale
        if kind == "Rigid Body":
            rot_axes = groups.get((kind, name, "Rotation"))
            bodies[name] = (pos, _motive_rotations(path, name, rot_axes, table, rotation_type))
        elif kind in ("Marker", "Rigid Body Marker", "Bone Marker"):
            markers[name] = pos
    if not markers and not bodies:
        raise ValueError(f"{path}: no marker or rigid-body position columns")
    return markers, bodies


def _motive_rotations(path: str, name: str, axes, table: np.ndarray, rotation_type: str):
    """(samples, 3, 3) rotations of one rigid body from its quaternion columns, NaN where it was
    not tracked."""
    if axes is None:
        raise ValueError(f"{path}: rigid body {name!r} has no Rotation columns")
    if rotation_type != "Quaternion":
        raise ValueError(
            f"{path}: Rotation Type {rotation_type!r} is not supported; export rigid "
            "bodies with Rotation Type 'Quaternion'"
        )
    quat = table[:, [axes["W"], axes["X"], axes["Y"], axes["Z"]]]
    ok = np.isfinite(quat).all(1)
    rot = np.full((len(table), 3, 3), np.nan)
    rot[ok] = quaternion_to_matrix(quat[ok])
    return rot


def motive_dataset(
    take: MotiveTake,
    names,
    sites,
    controls,
    *,
    control_time=None,
    payload_mass=None,
    orientation_names=None,
    window: float = 0.5,
    tolerance: float = 5e-4,
    **kwargs,
) -> MocapDataset:
    """Static frames of a Motive take with the robot's commands attached.

    Args:
        take: from :func:`read_motive_csv`.
        names: Motive marker (or rigid body) names, one per site.
        sites: ``(segment, s[, offset])`` per name.
        controls: (samples, n_tendons) at the take's times, or at ``control_time``.
        control_time: (k,) s, times of the controls in the take's clock; commands are steps
            (zero-order hold), so each mocap sample takes the last command before it.
        payload_mass: scalar, or per sample (like ``controls``).
        orientation_names: optional rigid-body names per site (None entries: no orientation).
        window, tolerance: the settle criterion (:func:`pacjax.static_frames`).
    """
    positions = take.positions(names)
    n = len(take.time)
    controls = np.asarray(controls, float)
    payload = None if payload_mass is None else np.asarray(payload_mass, float)
    if control_time is not None:
        control_time = np.asarray(control_time, float)
        if controls.ndim != 2 or controls.shape[0] != len(control_time):
            raise ValueError(
                f"controls must have shape ({len(control_time)}, n_tendons) like control_time"
            )
        idx = np.searchsorted(control_time, take.time, side="right") - 1
        before = idx < 0
        if np.all(before):
            raise ValueError("control_time starts after the take ends")
        keep = ~before
        positions, time = positions[keep], take.time[keep]
        controls = controls[idx[keep]]
        if payload is not None and payload.ndim == 1:
            payload = payload[idx[keep]]
    else:
        time = take.time
        if controls.shape[:1] != (n,):
            raise ValueError(
                f"controls must have one row per take sample ({n}), or pass control_time"
            )
        keep = np.ones(n, bool)
    if payload is not None and payload.ndim == 0:
        payload = np.full(len(time), float(payload))
    ori = None
    if orientation_names is not None:
        if len(orientation_names) != len(names):
            raise ValueError("orientation_names needs one entry (or None) per site")
        ori = np.full((len(time), len(names), 3, 3), np.nan)
        for j, body in enumerate(orientation_names):
            if body is not None:
                if body not in take.rigid_bodies:
                    raise ValueError(f"no rigid body named {body!r} in the take")
                ori[:, j] = take.rigid_bodies[body][1][keep]
    return MocapDataset.from_time_series(
        time,
        controls,
        positions,
        sites,
        window=window,
        tolerance=tolerance,
        payload_mass=payload,
        orientations=ori,
        **kwargs,
    )
