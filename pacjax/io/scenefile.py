"""Scene files: a robot, its model, tendons, loads, controls and solver options in TOML.

``load_scene(path)`` reads a file and returns ``(scene, controls, extra)``; ``scene_to_toml``
and ``save_scene`` write one. Every problem in a file (unknown key, wrong type, missing field,
a tendon on a segment that does not exist, ...) raises a :class:`ValueError` that names the
file, the table and the field, before anything is compiled or solved. SI units throughout,
except the documented ``*_deg`` angle fields.

A full example (every table is optional except ``[[segments]]``, or ``[preset]`` instead;
without ``[model]`` the model is PAC). Top-level keys (``controls``, ``markers``, ...) must come
before the first table, as TOML puts every later key into the table above it::

    name = "two-section arm"              # optional; default: the file's stem
    description = "anything"              # optional
    controls = [0.01]                     # optional: one per tendon (m pull-in, or N tension)
    markers = [[0, 0.5], [1, 1.0], [1, 1.0, [0.0, 0.02, 0.0]]]  # (segment, s[, local offset])

    [model]
    type = "PAC"                 # "PAC" | "PCC" | "PolynomialCurvature"
    frame = "torsion_free"       # PAC/PCC: "torsion_free" (default) | "paper"
    phi_stiffness = 1e-3         # PAC/PCC: factor on GJ / L for the stiffness on phi (optional)
    # order = 3                  # PolynomialCurvature: polynomial order (default 3)
    # twist = false              # PolynomialCurvature: add a torsion strain polynomial
    quadrature_points = 8        # Gauss-Legendre points per segment (optional)
    # rotation_substeps = 4      # Magnus sub-steps per segment (optional)
    # knot_grid = [8, 4]         # at least 8 intervals a segment, 4 position nodes each (optional)

    [[segments]]
    length = 0.1354              # m
    bending_stiffness = 0.1      # EI, N m^2
    axial_stiffness = 1078.0     # N/m
    torsion_stiffness = 0.0667   # GJ, N m^2 (optional: EI / 1.5)
    linear_density = 0.5465      # kg/m (optional: 0)
    radius = 0.03                # m (optional: 0)
    radius_tip = 0.02            # m, tapered segment (optional)
    stiffening = { type = "exponential", rate = 2.125 }   # EI grows with contraction (optional)
    contraction_limit = 0.070    # m, end stop of the contraction (optional: 0.9 * length)
    repeat = 2                   # this many identical segments (optional: 1)

    [[segments]]                 # from the material instead of the stiffnesses
    length = 0.2                 # m
    young_modulus = 1.2e6        # E, Pa (then no bending/axial/torsion_stiffness or
                                 # linear_density: they follow from the section)
    radius = 0.01                # m, outer radius at the base (required here)
    density = 1070.0             # kg/m^3 (optional: 0)
    poisson = 0.5                # (optional: 0.5)
    radius_tip = 0.006           # m, linear taper (optional)
    inner_radius = 0.003         # m, hollow section (optional: 0); inner_radius_tip likewise
    rest_curvature = [2.0, 0.0]  # the unloaded shape in this segment's model's coordinates
                                 # without dL (PCC: [c0, phi]; PAC: [c0, c1, phi]; polynomial:
                                 # its coefficients), rad per unit s (optional: straight)
    extensible = false           # no elongation coordinate (optional: true)
    # profile = { bending = [1.0, -0.8, 0.2], density = [1.0, -0.5] }  # instead of a taper:
                                 # EI(s)/EI(0) and rho A(s)/rho A(0) as polynomials in s
    model = "PCC"                # this segment's model, of [model]'s family (PCC with PAC,
                                 # polynomials of any order: a table such as
                                 # { type = "PolynomialCurvature", order = 0 }); optional

    [robot]
    mount = "hanging"            # "hanging" | "upright" | "horizontal", or:
    # base_rotation = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]   # base frame -> world
    base_position = [0.0, 0.0, 0.5]                      # m (optional: origin)

    [[tendons]]
    segment = 0                  # anchor segment (0 = base)
    angle_deg = 90.0             # around the cross-section from its x axis (or `angle`, rad)
    offset = 0.025               # m from the backbone
    s = 1.0                      # anchor within the segment (optional: 1)
    offset_end = 0.02            # m at the anchor, tapered routing (optional)
    bowden = false               # acts on its own segment only (optional: false)
    n_guides = 10                # evenly spaced guide rings per segment, or `guides = [s, ...]`
    routing = "rings"            # "rings" (chords between guide rings) | "channel" (a continuous
                                 # channel inside the body: no guides; optional: "rings")
    # angle_end_deg = 120.0      # channels only: angle at the anchor, a helical channel (or
                                 # `angle_end`, rad; optional: the angle at the entry)
    mode = "length"              # "length" (motor holds a length, control = pull-in, m) |
                                 # "tension" (control = tension, N)
    gain = 2e4                   # kappa_P, N/m (length mode)

    [[loads]]
    type = "gravity"             # g = 9.81, direction = [0, 0, -1] (world frame)
    [[loads]]
    type = "point_mass"          # mass (kg), segment, s (optional: 1)
    mass = 0.2
    segment = 1
    [[loads]]
    type = "point_force"         # force (N, world or local), segment, s, follower (optional)
    force = [0.5, 0.0, 0.0]
    segment = 1
    follower = true
    [[loads]]
    type = "point_moment"        # moment (N m), segment, s, follower (optional)
    moment = [0.0, 0.01, 0.0]
    segment = 1

    [solver]                     # keyword arguments of pacjax.solve_equilibrium
    tol = 1e-10
    max_steps = 100

A preset replaces ``[[segments]]``, ``[robot]`` and ``[[tendons]]``; ``[model]``, extra
``[[loads]]``, ``markers``, ``controls`` and ``[solver]`` still apply::

    controls = [0.02, 0, 0, 0, 0, 0, 0, 0, 0]
    [preset]
    name = "stella2023"          # or simply: preset = "stella2023"
    tip_mass = 0.2               # any keyword argument of pacjax.presets.stella2023
    mount = "hanging"

``extra`` holds ``name``, ``description``, ``preset`` (its name or None), ``solver`` (a dict
of keyword arguments for :func:`pacjax.solve_equilibrium`) and ``path``.
"""

from __future__ import annotations

import os

import numpy as np

from .._model.scene import Scene
from .scene_read import MOUNTS, PRESETS, scene_from_toml
from .scene_write import scene_to_toml

__all__ = ["load_scene", "scene_from_toml", "scene_to_toml", "save_scene", "PRESETS", "MOUNTS"]


def load_scene(path) -> tuple[Scene, np.ndarray | None, dict]:
    """Read a scene file. Returns ``(scene, controls or None, extra)`` (see the module doc).

    Raises:
        FileNotFoundError: no such file.
        ValueError: the file is not valid TOML or does not describe a valid scene; the
            message names the file, the table and the field.
    """
    path = os.fspath(path)
    with open(path, "rb") as f:
        raw = f.read()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ValueError(f"{path}: not a UTF-8 text file ({err})") from None
    stem = os.path.splitext(os.path.basename(path))[0]
    scene, controls, extra = scene_from_toml(text, source=path, default_name=stem)
    extra["path"] = path
    return scene, controls, extra


def save_scene(path, scene: Scene, controls=None, **kwargs) -> None:
    """Write ``scene`` (and optional ``controls``; see :func:`scene_to_toml`) to ``path``."""
    text = scene_to_toml(scene, controls, **kwargs)
    with open(os.fspath(path), "w", encoding="utf-8") as f:
        f.write(text)
