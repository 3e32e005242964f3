"""Ready-made scenes: the robot of the PAC paper (Stella, Guan, Leng, Della Santina, Hughes), and
a cast silicone tentacle whose tendons run in continuous channels (the robot of the motion-capture
data in ``shared/data/soromox_tentacle``, from the SoRoMoX paper).

Values the sources give are used as given; the others are estimates, each documented below with
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


#: The tentacle's two tapered pieces: (length m, radius at the base m, radius at the end m).
TENTACLE_PIECES = ((0.305, 0.01541, 0.00642), (0.055, 0.00642, 0.00480))
#: Young's modulus (Pa), Poisson's ratio and density (kg/m^3): the data's starting guess (the
#: publication identified E ~ 3.15e5 Pa and rho ~ 1320 kg/m^3 from the eight takes).
TENTACLE_MATERIAL = (5.05e5, 0.45, 1500.0)
#: Channel distance from the centreline at the base and at the anchor (end of piece 1), m:
#: d(s) = 0.0114 - 0.0295 s.
TENTACLE_CHANNEL = (0.0114, 0.0114 - 0.0295 * 0.305)
#: Marker sites (segment, s, offset in the cross-section frame, m) on their stalks. With the
#: hanging mount, local +x is world +x.
TENTACLE_MARKERS = (
    (0, 0.1291 / 0.305, (0.025, 0.0, 0.0)),
    (0, 0.2195 / 0.305, (-0.021, 0.0, 0.0)),
    (0, 0.2800 / 0.305, (0.020, 0.0, 0.0)),
    (1, 1.0, (0.0, 0.0, 0.008)),
)


def tentacle(
    model: StrainModel | None = None,
    *,
    routing: str = "channel",
    n_guides: int = 11,
    young_modulus: float = TENTACLE_MATERIAL[0],
    poisson: float = TENTACLE_MATERIAL[1],
    density: float = TENTACLE_MATERIAL[2],
    mount: str = "hanging",
    loads: tuple = (),
    quadrature_points: int = 8,
) -> Scene:
    """A cast silicone tentacle, 0.36 m, solid round section tapered in two pieces, with two
    tendons in continuous channels anchored at the end of the first piece.

    The robot of ``shared/data/soromox_tentacle`` (its README gives the geometry): the channels
    run from 11.4 mm off the centreline at the base to 2.4 mm at the anchor, at 60 degrees either
    side of world +x (tendon 0 towards world +y, tendon 1 towards -y, hanging). Both tendons are
    in tension mode: controls (2,) are tensions in N. Markers as in the data (three on stalks
    along the body, one 8 mm beyond the tip).

    Section stiffness from the material (:meth:`Segment.from_material`): the axial stiffness of
    a linear taper under an end load, ``E pi r0 r1 / L``, is the least elastic energy of any
    axial strain along the piece with the same total elongation, which is what the one
    elongation coordinate measures; a uniform stretch, as in SoRoMoX's strain basis, is 27 %
    stiffer for the first piece.

    Args:
        model: strain model (default :class:`PAC`, frame ``"torsion_free"``), or one per piece
            (the data's reference model is affine then constant curvature: ``(PAC(), PCC())``).
        routing: ``"channel"`` (as built) or ``"rings"`` (the same channels sampled by
            ``n_guides`` rings per piece: chords, for comparison).
        n_guides: rings per piece with ``routing="rings"``.
        young_modulus, poisson, density: the silicone (Pa, -, kg/m^3).
        mount: see :data:`MOUNTS` (the data hang).
        loads: extra loads (gravity is always there).
        quadrature_points: Gauss-Legendre points per segment.
    """
    if mount not in MOUNTS:
        raise ValueError(f"mount must be one of {tuple(MOUNTS)}, got {mount!r}")
    segments = [
        Segment.from_material(
            length,
            young_modulus=young_modulus,
            poisson=poisson,
            density=density,
            radius=r0,
            radius_tip=r1,
        )
        for length, r0, r1 in TENTACLE_PIECES
    ]
    robot = Robot(segments, base_rotation=MOUNTS[mount])
    routed = (
        {"routing": "channel"}
        if routing == "channel"
        else {"routing": routing, "guides": np.linspace(0.0, 1.0, n_guides).tolist()}
    )
    # Hanging, the base frame's y is world -y: the tendon towards world +y sits at -60 degrees.
    tendons = [
        Tendon(
            segment=0,
            angle=angle,
            offset=TENTACLE_CHANNEL[0],
            offset_end=TENTACLE_CHANNEL[1],
            mode="tension",
            **routed,
        )
        for angle in (-math.pi / 3, math.pi / 3)
    ]
    return Scene(
        robot,
        PAC() if model is None else model,
        tendons=tendons,
        loads=[Gravity(), *loads],
        markers=TENTACLE_MARKERS,
        quadrature_points=quadrature_points,
    )
