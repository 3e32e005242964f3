"""Ready-made scenes: the robot of the PAC paper (Stella, Guan, Leng, Della Santina, Hughes).

Values the paper gives are used as given; the others are estimates, each documented below with
its reasoning, so that a lab with the real robot knows what to identify
(:func:`pacjax.identify`) first.
"""

import math

import numpy as np

from ._model.loads import Gravity, PointMass
from ._model.robot import ExponentialStiffening, Robot, Segment
from ._model.scene import Scene
from ._model.strain import PAC, StrainModel
from ._model.tendons import Tendon

#: Free (quasi-static) length of one segment, m. Paper: "stabilized around 135.4 mm".
SEGMENT_LENGTH = 0.1354
#: Axial stiffness, N/m. Paper: linear fit of the compression test, 1.078 N/mm.
AXIAL_STIFFNESS = 1078.0
#: Contraction range, m. Paper: compressed "from 0 to 70 mm".
CONTRACTION_RANGE = 0.070
#: Bending stiffness EI at rest, N m^2. ESTIMATE: the paper shows the shear test but no value.
#: 0.1 N m^2 makes a 200 g tip load on one horizontal segment deflect ~16 mm (12 % of L,
#: P L^3 / 3 EI), the moderate, clearly non-constant curvature the paper's loaded poses show.
BENDING_STIFFNESS = 0.1
#: Stiffening with contraction. ESTIMATE: the paper reports that bending stiffness "increases
#: significantly" with contraction; we take 3x at the full 70 mm contraction (52 % of L), with
#: the smooth law EI(dL) = EI exp(rate (-dL / L)).
STIFFENING_RATE = math.log(3.0) / (CONTRACTION_RANGE / SEGMENT_LENGTH)
#: Linear density, kg/m. ESTIMATE: 12 TPU sine-wave rings (3 mm x 6 mm section, ~60 mm
#: diameter, path ~1.5x the circumference, TPU 1210 kg/m^3) weigh ~6 g each: ~74 g per segment.
LINEAR_DENSITY = 0.074 / SEGMENT_LENGTH
#: Outer radius, m. ESTIMATE from the ring diameter above.
RADIUS = 0.030
#: Mass of the rigid end ring at each segment's tip (tendon anchors, Bowden terminations), kg.
#: ESTIMATE.
END_RING_MASS = 0.015
#: Radial offset of the tendons from the backbone, m. ESTIMATE: ring radius minus the hole margin.
TENDON_OFFSET = 0.025
#: Motor gain kappa_P, N/m. The paper uses 20 "in its units" for the Dynamixel loop; read as
#: 20 N/mm, stiff against the body's 1.078 N/mm, as position-controlled motors are.
TENDON_GAIN = 2.0e4
#: Angles of the three tendons of each section, rad (120 degrees apart).
TENDON_ANGLES = (math.pi / 2, math.pi / 2 + 2 * math.pi / 3, math.pi / 2 + 4 * math.pi / 3)
#: Guide rings per segment (the tendon passes through each; frictionless pulleys).
GUIDES = tuple(np.linspace(0.0, 1.0, 10).tolist())

#: Base rotations (base frame -> world) of the supported mounts.
MOUNTS = {
    # base rotation taking the robot's rest axis (+z of the base frame) to the world
    "hanging": np.diag([1.0, -1.0, -1.0]),  # axis along -z (world), the paper's set-up
    "upright": np.eye(3),
    "horizontal": np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]),  # axis +x
}


def stella2023(
    model: StrainModel | None = None,
    *,
    tip_mass: float = 0.0,
    mount: str = "hanging",
    n_sections: int = 3,
    stiffening: bool = True,
    loads: tuple = (),
    quadrature_points: int = 8,
) -> Scene:
    """The paper's three-section tendon-driven robot.

    Each section is one segment with three tendons at 120 degrees; section 1's tendons run from
    the base (free routing), sections 2 and 3 are driven through Bowden cables (each acts on its
    own segment only). Markers sit at the base, and at the midpoint and end of every segment.
    Controls (9,) are tendon pull-ins in metres, section by section.

    Args:
        model: strain model (default :class:`PAC`).
        tip_mass: payload (kg) hanging at the tip (paper: 0, 0.2, 0.4).
        mount: ``"hanging"`` (base up, robot along -z, default), ``"upright"`` or
            ``"horizontal"``: only the base rotation changes.
        n_sections: number of sections (1 for the paper's single-section study).
        stiffening: bending stiffness grows with contraction (see ``STIFFENING_RATE``).
        loads: extra loads (e.g. a :class:`PointForce` for the human-interaction experiment).
        quadrature_points: Gauss-Legendre points per segment.
    """
    if mount not in MOUNTS:
        raise ValueError(f"mount must be one of {tuple(MOUNTS)}, got {mount!r}")
    if n_sections < 1:
        raise ValueError(f"n_sections must be >= 1, got {n_sections}")
    law = ExponentialStiffening(STIFFENING_RATE) if stiffening else None
    segment = Segment(
        length=SEGMENT_LENGTH,
        bending_stiffness=BENDING_STIFFNESS,
        axial_stiffness=AXIAL_STIFFNESS,
        linear_density=LINEAR_DENSITY,
        radius=RADIUS,
        stiffening=law,
        contraction_limit=CONTRACTION_RANGE,
    )
    robot = Robot([segment] * n_sections, base_rotation=MOUNTS[mount])
    tendons = [
        Tendon(
            segment=k,
            angle=angle,
            offset=TENDON_OFFSET,
            bowden=k > 0,
            guides=GUIDES,
            gain=TENDON_GAIN,
        )
        for k in range(n_sections)
        for angle in TENDON_ANGLES
    ]
    all_loads = [Gravity()]
    all_loads += [PointMass(END_RING_MASS, k, 1.0) for k in range(n_sections)]
    if tip_mass:
        all_loads.append(PointMass(tip_mass, n_sections - 1, 1.0))
    all_loads += list(loads)
    sites = [(0, 0.0)] + [(k, s) for k in range(n_sections) for s in (0.5, 1.0)]
    return Scene(
        robot,
        PAC() if model is None else model,
        tendons=tendons,
        loads=all_loads,
        markers=sites,
        quadrature_points=quadrature_points,
    )
