"""Motion-capture files: the pacjax static-frame CSV (OptiTrack Motive exports:
:mod:`pacjax.io.motive`).

The pacjax mocap CSV
--------------------
One row per static frame. Header lines start with ``#`` and hold ``key = JSON value``; then one
line of column names, then the data. SI units: metres, kilograms, newtons, seconds. An empty
cell or ``nan`` is a missing value (only allowed for markers and orientations: the marker is
masked in that frame, the frame is kept)::

    # pacjax mocap 1
    # sites = [[0, 0.5], [0, 1.0], [1, 1.0, [0.0, 0.012, 0.0]]]
    # payload_site = [1, 1.0]           (optional; default: the tip)
    # force_site = [1, 1.0]             (optional; default: the tip)
    # force_follower = false            (optional)
    # length_unit = "m"                 (optional: "m" (default), "mm" or "cm")
    frame,time,u0,u1,u2,payload_mass,m0_x,m0_y,m0_z,m1_x,m1_y,m1_z,m2_x,m2_y,m2_z
    0,0.0,0.01,0.0,0.0,0.2,0.001,-0.002,-0.068,...

Columns:

- ``u0 .. u{n-1}`` (one per tendon; none for a robot without tendons): controls in the
  scene's order: pull-in (m) of a length-mode tendon (0 = rest length, positive = shortened),
  or tension (N) of a tension-mode tendon.
- ``m{j}_x, m{j}_y, m{j}_z`` (required for each site j): marker position in the motion-capture
  frame. ``sites`` lists, per marker, ``[segment, s]`` or ``[segment, s, [ox, oy, oz]]``:
  segment index from 0 at the base, ``s`` in [0, 1] along it, and the marker's stand-off from
  the backbone in the local cross-section frame (m).
- ``m{j}_qw, m{j}_qx, m{j}_qy, m{j}_qz`` (optional, all markers or none): orientation at site j
  as a unit quaternion (mocap frame; e.g. a rigid body at the tip).
- ``base_qw, base_qx, base_qy, base_qz`` (optional, all four or none): the robot base's
  orientation in that frame (base frame -> world, unit quaternion), for data taken with the
  base turned from frame to frame.
- ``gravity_x, gravity_y, gravity_z`` (optional, all three or none): the unit direction of
  gravity (world frame) in that frame, replacing the scene's ``Gravity`` direction.
- ``holdout`` (optional): 1 for a frame that ``pacjax fit`` holds out of the fit and reports
  as held-out, 0 otherwise.
- ``payload_mass`` (optional): kg hanging at ``payload_site``.
- ``force_x, force_y, force_z`` (optional): N at ``force_site``; world frame (the mocap frame's
  axes are not used: the force is in the scene's world frame) or, with ``force_follower``, the
  local cross-section frame.
- ``frame``, ``time`` (optional): labels, not used by the fit.

Any other column is an error (so that a typo does not silently drop data).
"""

from __future__ import annotations

import csv
import json
import os

import numpy as np

from .._identify.dataset import MocapDataset

__all__ = ["load_mocap", "save_mocap", "quaternion_to_matrix", "matrix_to_quaternion"]

_UNITS = {"m": 1.0, "mm": 1e-3, "cm": 1e-2}
_HEADER_KEYS = ("sites", "payload_site", "force_site", "force_follower", "length_unit")


def quaternion_to_matrix(q) -> np.ndarray:
    """Rotation matrices (..., 3, 3) from quaternions (..., 4) ordered ``(w, x, y, z)``."""
    q = np.asarray(q, float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def matrix_to_quaternion(r) -> np.ndarray:
    """Quaternions (..., 4) ``(w, x, y, z)`` with ``w >= 0`` from rotation matrices."""
    r = np.asarray(r, float)
    flat = r.reshape(-1, 3, 3)
    out = np.empty((len(flat), 4))
    for k, m in enumerate(flat):
        # Symmetric 4x4 (Bar-Itzhack): the quaternion is its dominant eigenvector.
        k4 = (
            np.array(
                [
                    [
                        m[0, 0] - m[1, 1] - m[2, 2],
                        m[1, 0] + m[0, 1],
                        m[2, 0] + m[0, 2],
                        m[2, 1] - m[1, 2],
                    ],
                    [
                        m[1, 0] + m[0, 1],
                        m[1, 1] - m[0, 0] - m[2, 2],
                        m[2, 1] + m[1, 2],
                        m[0, 2] - m[2, 0],
                    ],
                    [
                        m[2, 0] + m[0, 2],
                        m[2, 1] + m[1, 2],
                        m[2, 2] - m[0, 0] - m[1, 1],
                        m[1, 0] - m[0, 1],
                    ],
                    [
                        m[2, 1] - m[1, 2],
                        m[0, 2] - m[2, 0],
                        m[1, 0] - m[0, 1],
                        m[0, 0] + m[1, 1] + m[2, 2],
                    ],
                ]
            )
            / 3.0
        )
        if not np.all(np.isfinite(k4)):
            out[k] = np.nan
            continue
        _, vec = np.linalg.eigh(k4)
        x, y, z, w = vec[:, -1]
        out[k] = np.array([w, x, y, z]) * (1.0 if w >= 0 else -1.0)
    return out.reshape(r.shape[:-2] + (4,))


# ------------------------------------------------------------------------------ pacjax CSV
def save_mocap(path, dataset: MocapDataset) -> None:
    """Write ``dataset`` in the pacjax mocap CSV format (see the module docstring)."""
    d = dataset
    header = {
        "sites": [[seg, s] if not any(off) else [seg, s, list(off)] for seg, s, off in d.sites]
    }
    if d.payload_site is not None:
        header["payload_site"] = list(d.payload_site)
    if d.force is not None:
        if d.force_site is not None:
            header["force_site"] = list(d.force_site)
        header["force_follower"] = d.force_follower
    columns = ["frame"] + (["time"] if d.time is not None else [])
    columns += [f"u{i}" for i in range(d.n_controls)]
    blocks = [np.arange(d.n_frames)[:, None]] + ([d.time[:, None]] if d.time is not None else [])
    blocks.append(d.controls)
    if d.payload_mass is not None:
        columns.append("payload_mass")
        blocks.append(d.payload_mass[:, None])
    if d.force is not None:
        columns += ["force_x", "force_y", "force_z"]
        blocks.append(d.force)
    if d.base_rotation is not None:
        columns += [f"base_q{a}" for a in "wxyz"]
        blocks.append(matrix_to_quaternion(d.base_rotation))
    if d.gravity_direction is not None:
        columns += [f"gravity_{a}" for a in "xyz"]
        blocks.append(d.gravity_direction)
    if d.holdout is not None:
        columns.append("holdout")
        blocks.append(d.holdout[:, None].astype(float))
    for j in range(d.n_markers):
        columns += [f"m{j}_{a}" for a in "xyz"]
    blocks.append(d.markers.reshape(d.n_frames, -1))
    if d.orientations is not None:
        for j in range(d.n_markers):
            columns += [f"m{j}_q{a}" for a in "wxyz"]
        blocks.append(matrix_to_quaternion(d.orientations).reshape(d.n_frames, -1))
    table = np.concatenate(blocks, axis=1)
    with open(os.fspath(path), "w", encoding="utf-8", newline="") as f:
        f.write("# pacjax mocap 1\n")
        for key, value in header.items():
            f.write(f"# {key} = {json.dumps(value)}\n")
        writer = csv.writer(f)
        writer.writerow(columns)
        for k, row in enumerate(table):
            cells = ["" if not np.isfinite(v) else repr(float(v)) for v in row]
            cells[0] = str(k)
            writer.writerow(cells)


def number_cell(text: str, where: str) -> float:
    """A CSV cell as a number: empty or ``nan`` is NaN; anything else not a number raises a
    ValueError naming ``where``."""
    text = text.strip()
    if text == "" or text.lower() == "nan":
        return np.nan
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"{where}: {text!r} is not a number") from None


def load_mocap(path) -> MocapDataset:
    """Read a pacjax mocap CSV (see the module docstring); errors name the file and column."""
    path = os.fspath(path)
    with open(path, encoding="utf-8", newline="") as f:
        lines = f.read().splitlines()
    header, body_start = _read_header(path, lines)
    columns, data = _read_rows(path, lines[body_start:])
    scale = _length_scale(path, header)
    n_markers = len(header["sites"])
    table = _Columns(path, columns, data)
    n_u = _check_columns(path, table, n_markers)
    controls = table.stack([f"u{i}" for i in range(n_u)]) if n_u else np.zeros((len(data), 0))
    if np.any(np.isnan(controls)):
        raise ValueError(f"{path}: controls (u columns) must not be empty or NaN")
    markers = (
        np.stack([table.stack([f"m{j}_{a}" for a in "xyz"]) for j in range(n_markers)], 1) * scale
    )
    payload = table.get("payload_mass") if "payload_mass" in table else None
    force = _read_force(path, table)
    orientations = _read_orientations(path, table, n_markers)
    base_rotation = _read_base_rotation(path, table)
    gravity = _read_triple(path, table, "gravity", "the gravity direction")
    if gravity is not None:
        norm = np.linalg.norm(gravity, axis=1, keepdims=True)
        if not np.all(np.abs(norm - 1.0) < 1e-3):
            bad = int(np.flatnonzero(np.abs(norm[:, 0] - 1.0) >= 1e-3)[0])
            raise ValueError(f"{path}: gravity_x/y/z of row {bad} is not a unit vector")
        gravity = gravity / norm
    try:
        return MocapDataset.from_arrays(
            controls,
            markers,
            [tuple(s) if not isinstance(s, list) else tuple(s) for s in header["sites"]],
            payload,
            payload_site=header.get("payload_site"),
            force=force,
            force_site=header.get("force_site"),
            force_follower=bool(header.get("force_follower", False)),
            orientations=orientations,
            time=table.get("time") if "time" in table else None,
            base_rotation=base_rotation,
            gravity_direction=gravity,
            holdout=table.get("holdout") if "holdout" in table else None,
        )
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None


def _read_header(path: str, lines: list[str]) -> tuple[dict, int]:
    """The ``# key = JSON value`` lines at the top: ``(header, index of the column line)``.

    ``#`` lines without ``=`` (the ``# pacjax mocap 1`` tag, remarks) are skipped; an unknown key
    is an error, so that a typo does not silently drop a setting.
    """
    header: dict = {}
    body_start = 0
    for k, line in enumerate(lines):
        if not line.startswith("#"):
            body_start = k
            break
        text = line[1:].strip()
        if "=" not in text:
            continue
        key, value = (x.strip() for x in text.split("=", 1))
        if key not in _HEADER_KEYS:
            raise ValueError(
                f"{path}: unknown header key {key!r} (known: {', '.join(_HEADER_KEYS)})"
            )
        try:
            header[key] = json.loads(value)
        except json.JSONDecodeError:
            raise ValueError(f"{path}: header {key!r} is not valid JSON: {value!r}") from None
    else:
        raise ValueError(f"{path}: no column line after the header")
    if "sites" not in header:
        raise ValueError(f"{path}: the header must give the marker sites ('# sites = [[0, 1.0]]')")
    return header, body_start


def _read_rows(path: str, lines: list[str]) -> tuple[list[str], list[list[str]]]:
    """``(column names, data rows)`` of the CSV body; blank rows are dropped, every other row
    must have one cell per column."""
    rows = list(csv.reader(lines))
    columns = [c.strip() for c in rows[0]]
    data = [r for r in rows[1:] if any(c.strip() for c in r)]
    if not data:
        raise ValueError(f"{path}: no data rows")
    for k, r in enumerate(data):
        if len(r) != len(columns):
            raise ValueError(
                f"{path}: data row {k} has {len(r)} cells, the column line has {len(columns)}"
            )
    return columns, data


def _length_scale(path: str, header: dict) -> float:
    """Metres per length unit of the marker columns (the header's ``length_unit``)."""
    unit = header.get("length_unit", "m")
    if unit not in _UNITS:
        raise ValueError(f"{path}: length_unit must be one of {list(_UNITS)}, got {unit!r}")
    return _UNITS[unit]


class _Columns:
    """The data rows by column name; cells are parsed when a column is read, so that an error
    names the column and the row."""

    def __init__(self, path: str, columns: list[str], data: list[list[str]]):
        self.path, self.columns, self.data = path, columns, data
        self.index = {name: i for i, name in enumerate(columns)}
        if len(self.index) != len(columns):
            raise ValueError(f"{path}: duplicate column names")

    def __contains__(self, name: str) -> bool:
        return name in self.index

    def get(self, name: str) -> np.ndarray:
        """(frames,) values of one column, NaN where empty."""
        i, where = self.index[name], f"{self.path}, column {name}"
        return np.array([number_cell(r[i], f"{where}, row {k}") for k, r in enumerate(self.data)])

    def stack(self, names) -> np.ndarray:
        """(frames, len(names)) values of several columns."""
        return np.stack([self.get(name) for name in names], 1)


def _check_columns(path: str, table: _Columns, n_markers: int) -> int:
    """The number of controls (``u0``, ``u1``, ... without a gap), after checking that every
    column is known and that every site has its marker columns."""
    n_u = 0
    while f"u{n_u}" in table:
        n_u += 1
    known = {"frame", "time", "payload_mass", "force_x", "force_y", "force_z"}
    known |= {f"base_q{a}" for a in "wxyz"} | {f"gravity_{a}" for a in "xyz"} | {"holdout"}
    known |= {f"u{i}" for i in range(n_u)}
    known |= {f"m{j}_{a}" for j in range(n_markers) for a in "xyz"}
    known |= {f"m{j}_q{a}" for j in range(n_markers) for a in "wxyz"}
    unknown = [c for c in table.columns if c not in known]
    if unknown:
        raise ValueError(
            f"{path}: unknown column(s) {unknown} (controls u0..u{n_u - 1}, markers m0..m"
            f"{n_markers - 1} from the header's sites; see pacjax.io.mocapfile)"
        )
    missing = [f"m{j}_{a}" for j in range(n_markers) for a in "xyz" if f"m{j}_{a}" not in table]
    if missing:
        raise ValueError(f"{path}: missing marker column(s) {missing[:6]} for the header's sites")
    return n_u


def _read_force(path: str, table: _Columns) -> np.ndarray | None:
    """(frames, 3) N from ``force_x, force_y, force_z`` (all three or none), else None."""
    return _read_triple(path, table, "force", "force")


def _read_triple(path: str, table: _Columns, prefix: str, what: str) -> np.ndarray | None:
    """(frames, 3) from ``{prefix}_x, _y, _z`` (all three or none), else None."""
    names = tuple(f"{prefix}_{a}" for a in "xyz")
    present = [c for c in names if c in table]
    if not present:
        return None
    if len(present) != 3:
        raise ValueError(f"{path}: {what} needs all of {', '.join(names)}")
    return table.stack(names)


def _read_base_rotation(path: str, table: _Columns) -> np.ndarray | None:
    """(frames, 3, 3) base rotations from ``base_q{w,x,y,z}`` (all four or none), else None."""
    names = [f"base_q{a}" for a in "wxyz"]
    present = [c for c in names if c in table]
    if not present:
        return None
    if len(present) != 4:
        raise ValueError(f"{path}: the base orientation needs all of {', '.join(names)}")
    quats = table.stack(names)
    norm = np.linalg.norm(quats, axis=1)
    bad = ~np.isfinite(norm) | (np.abs(norm - 1.0) > 1e-3)
    if bad.any():
        raise ValueError(
            f"{path}: base_q* of row {int(np.flatnonzero(bad)[0])} is not a unit quaternion"
        )
    return quaternion_to_matrix(quats / norm[:, None])


def _read_orientations(path: str, table: _Columns, n_markers: int) -> np.ndarray | None:
    """(frames, markers, 3, 3) rotations from the ``m{j}_q{w,x,y,z}`` columns (every marker's or
    none), else None."""
    names = [f"m{j}_q{a}" for j in range(n_markers) for a in "wxyz"]
    if not any(c in table for c in names):
        return None
    absent = [c for c in names if c not in table]
    if absent:
        raise ValueError(f"{path}: orientation columns incomplete, missing {absent[:4]}")
    quats = np.stack([table.stack([f"m{j}_q{a}" for a in "wxyz"]) for j in range(n_markers)], 1)
    return quaternion_to_matrix(quats)


#: The Motive importer's names, moved to :mod:`pacjax.io.motive`.
_MOVED_TO_MOTIVE = ("read_motive_csv", "motive_dataset", "MotiveTake")


def __getattr__(name: str):
    if name in _MOVED_TO_MOTIVE:
        from .. import _deprecated
        from . import motive

        _deprecated.warn(f"pacjax.io.mocapfile.{name}", f"pacjax.io.motive.{name}")
        return getattr(motive, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
