"""Strain models: the only thing in which PCC, PAC and polynomial curvature differ.

A strain model maps the coordinates of one segment, ``q_i``, to

- the body-frame strain ``u(s) = (u_x, u_y, u_z)`` per unit normalised arc length ``s``:
  ``u_x, u_y`` are bending (rotation rates about the cross-section axes x and y), ``u_z`` is
  twist; the frame obeys ``R'(s) = R(s) [u(s)]x``;
- an optional rotation of the frame at ``s = 0`` (the paper's convention twists the frame by
  ``phi`` at the base of a segment);
- the elongation ``dL`` of the segment (always the last coordinate).

Everything else (kinematics, energies, solvers) is shared. The *bending vector* ``(k_x, k_y)``
points to where the backbone curves: a positive ``k_x`` bends the tip towards the cross-section's
+x axis, which is a rotation about +y, so ``u = (-k_y, k_x, twist)``.
"""

import abc
import dataclasses

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._config import MATMUL_PRECISION
from .rotation import hat, rot_z
from .trig import library_sincos, sin_cos_versine, sincos

_FRAMES = ("torsion_free", "paper")


class StrainModel(eqx.Module):
    """Abstract strain model (one per scene, the same for every segment)."""

    @abc.abstractmethod
    def dofs_per_segment(self) -> int:
        """Number of coordinates per segment."""

    @abc.abstractmethod
    def coordinate_names(self) -> tuple[str, ...]:
        """Names of the coordinates of one segment, in order."""

    @abc.abstractmethod
    def strain(self, q: Float[Array, " d"], s: Float[Array, ""]) -> Float[Array, "3"]:
        """Body-frame strain ``(u_x, u_y, u_z)`` (rad per unit ``s``) at ``s``."""

    def base_rotation(self, q: Float[Array, " d"]) -> Float[Array, "3 3"] | None:
        """Rotation of the segment frame at ``s = 0`` relative to the previous frame, or None."""
        return None

    def elongation(self, q: Float[Array, " d"]) -> Float[Array, ""]:
        """Change of length ``dL`` (m) of the segment."""
        return q[-1]

    def coordinate_energy(
        self, q: Float[Array, " d"], torsion_stiffness: Float[Array, ""]
    ) -> Float[Array, ""] | None:
        """Elastic energy on coordinates that are not a strain (PAC's ``phi``), or None.

        ``torsion_stiffness`` is the segment's ``GJ / L`` (N m).
        """
        return None

    def has_twist_strain(self) -> bool:
        """Whether ``u_z`` can be non-zero (then the torsion energy is integrated)."""
        return False

    def stiffness_scale(self, diagonal: Float[Array, "n d"]) -> Float[Array, "n d"]:
        """Per-coordinate stiffness scale from the elastic Hessian's diagonal (default: as is)."""
        return diagonal

    def strain_degree(self) -> int:
        """Polynomial degree of the strain in ``s`` (the elastic energy has twice that)."""
        return 0

    def exact_rotation_substeps(self) -> int:
        """Magnus sub-steps per segment that integrate this model's rotation exactly (or well)."""
        return 1

    def plane_frames(
        self, q: Float[Array, " d"], s: Float[Array, "*p"]
    ) -> tuple[Float[Array, "*p 3 3"], Float[Array, "*p 3"]] | None:
        """Closed-form rotations (base rotation included) and tangents ``R e_z`` at the points
        ``s``, for models whose segments bend in one fixed plane; None for the others, which
        the kinematics integrates with the Magnus method."""
        return None

    def plane_angle_basis(self, s: Float[Array, "*p"]) -> Float[Array, "*p m"] | None:
        """For models with :meth:`plane_frames`: ``d theta / d q[:m]`` at ``s``, the bending
        angle being linear in the ``m = d - 2`` curvature coordinates (then ``phi = q[-2]``,
        ``dL = q[-1]``, and the frames depend on ``q`` only through ``theta(s)`` and ``phi``:
        :func:`pacjax._model.kinematics.segment_knot_jacobian`). None for the other models."""
        return None

    def frames_independent_of_knots(self) -> bool:
        """True when the frames and positions do not depend on where the kinematics places its
        knots, to about 1e-12 relative (closed-form rotations, converged position quadrature):
        then a point's Jacobian may come from any evaluation of the kinematics. False for models
        whose rotation is integrated step by step (the result moves with the knots, e.g.
        ``PolynomialCurvature(2)``: 2e-8 relative between two knot sets at curvatures ~1)."""
        return self.plane_frames(jnp.zeros(self.dofs_per_segment()), jnp.zeros(1)) is not None

    def bending_vector(self, q: Float[Array, " d"], s: Float[Array, ""]) -> Float[Array, "2"]:
        """``(k_x, k_y)``: curvature per unit ``s`` towards the cross-section's x and y axes."""
        u = self.strain(q, s)
        return jnp.stack([u[1], -u[0]])

    def newton_from_start(self) -> bool:
        """Whether the solver may take Newton steps from a start where the stiffness is
        positive definite (:class:`pacjax._statics.ptc.PseudoTransientContinuation`'s
        ``newton_start``): True for strain coordinates, in which the energy of a tendon or a
        load is close to quadratic over a step."""
        return True

    def embedding(self, host: "StrainModel") -> tuple[int, ...] | None:
        """Where each of this model's coordinates sits among ``host``'s, when ``host``'s
        kinematics with the other coordinates at zero is exactly this model's (PCC is PAC with
        ``c1 = 0``; a polynomial is one of a higher order with zero top coefficients); None
        when it is not. A scene mixes models through their common host
        (:func:`common_family`)."""
        return tuple(range(self.dofs_per_segment())) if host == self else None

    def free_plane_angle(self) -> int | None:
        """Index of a bending-plane angle that is undefined on a straight segment (the shape
        does not depend on it there), or None. The solver turns it to the force before it
        starts (:meth:`pacjax._statics.problem.ScaledProblem.aligned`)."""
        return None


def _check_frame(frame: str) -> None:
    if frame not in _FRAMES:
        raise ValueError(f"frame must be one of {_FRAMES}, got {frame!r}")


def _angle_coefficients(
    theta, order: int, pair
) -> list[tuple[Float[Array, "*p"], Float[Array, "*p"]]]:
    """``(sin t, 1 - cos t)`` at ``t = theta`` and their derivatives up to ``order`` (the
    coefficient of ``B0`` is 1, and 0 in every derivative); ``pair`` computes sines and cosines
    (:func:`pacjax._model.trig.sin_cos_versine`)."""
    st, ct, vers = sin_cos_versine(theta, pair)
    return [(st, vers), (ct, st), (-st, ct)][: order + 1]


def _matrix(rows) -> Float[Array, "3 3"]:
    return jnp.stack([jnp.stack(r) for r in rows])


class PlanarCurvature(StrainModel):
    """Curvature polynomial ``c(s)`` in a bending plane at angle ``phi``: PCC and PAC."""

    frame: str = eqx.field(static=True, default="torsion_free")
    phi_stiffness: float | None = eqx.field(static=True, default=None)
    # Sines and cosines as fused arithmetic instead of library calls (pacjax._model.trig):
    # faster to run, slower to compile; pacjax.simulate turns it on for the scene it integrates.
    fused_trig: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        _check_frame(self.frame)
        if self.phi_stiffness is not None and not self.phi_stiffness >= 0:
            raise ValueError(f"phi_stiffness must be >= 0, got {self.phi_stiffness}")

    def sincos(self, x):
        """``(sin x, cos x)`` in the form :attr:`fused_trig` chooses."""
        return sincos(x) if self.fused_trig else library_sincos(x)

    def with_fused_trig(self) -> "PlanarCurvature":
        """The same model with :attr:`fused_trig` on."""
        return dataclasses.replace(self, fused_trig=True)

    def phi_stiffness_factor(self) -> float:
        """Factor on ``GJ / L`` giving the stiffness on ``phi``.

        With ``frame="paper"`` the frame is twisted by ``phi``: a real torsion, factor 1 (the
        paper's ``k_torsion``). With the torsion-free frame ``phi`` is only the direction of the
        bending plane; its stiffness is a regulariser (default 1e-6, energy
        ``k (1 - cos phi)``) that keeps the Hessian regular at zero curvature, where ``phi`` is
        undefined, while biasing the plane of a bent segment by a relative amount of that order.
        """
        if self.phi_stiffness is not None:
            return self.phi_stiffness
        return 1.0 if self.frame == "paper" else 1e-6

    def newton_from_start(self) -> bool:
        # Polar coordinates: near straight the energy along the plane angle scales with the
        # curvature, and a Newton step swings the plane far past the solution (more steps in
        # all than the continuation from the start: benchmarks/RESULTS.md).
        return False

    def embedding(self, host):
        if not (
            isinstance(host, PlanarCurvature)
            and host.frame == self.frame
            and host.phi_stiffness == self.phi_stiffness
            and host.strain_degree() >= self.strain_degree()
        ):
            return None
        m, d = self.dofs_per_segment() - 2, host.dofs_per_segment()
        # Curvature coefficients (monomials in s, nested), then phi and dL.
        return (*range(m), d - 2, d - 1)

    def free_plane_angle(self) -> int | None:
        # The curvature coordinates come first, then phi, then dL. In the paper's frame phi
        # also twists the frame (everything distal to it), so it is not free.
        return self.dofs_per_segment() - 2 if self.frame == "torsion_free" else None

    @abc.abstractmethod
    def _curvature(self, q: Float[Array, " d"], s: Float[Array, ""]) -> Float[Array, ""]: ...

    @abc.abstractmethod
    def bending_angle(self, q: Float[Array, " d"], s: Float[Array, "*p"]) -> Float[Array, "*p"]:
        """Bending angle ``theta(s) = int_0^s c(t) dt`` (rad)."""

    @abc.abstractmethod
    def plane_angle_basis(self, s): ...

    def plane_frames(self, q, s):
        return self.plane_rotation_tangent(self.bending_angle(q, s), q[-2])

    def plane_rotation_tangent(
        self, theta: Float[Array, "*p"], phi: Float[Array, ""]
    ) -> tuple[Float[Array, "*p 3 3"], Float[Array, "*p 3"]]:
        """Rotation (base rotation included) and tangent ``R e_z`` at bending angle ``theta``
        in the plane at angle ``phi``."""
        # Entry by entry: the energy's automatic derivatives (the residual, and its Jacobian at
        # a solution) run faster through this than through the matrices of the jet.
        st, ct, versine = sin_cos_versine(theta, self.sincos)
        sp, cp = self.sincos(phi)
        zero = jnp.zeros_like(theta)
        tangent = jnp.stack([cp * st, sp * st, ct], axis=-1)
        if self.frame == "paper":
            rows = [[cp * ct, -sp + zero, cp * st], [sp * ct, cp + zero, sp * st], [-st, zero, ct]]
        else:
            # Rz(phi) Ry(theta) Rz(-phi), with cos theta - 1 from the versine, which keeps its
            # relative precision near the straight configuration.
            vers = -versine
            rows = [
                [1.0 + cp * cp * vers, cp * sp * vers, cp * st],
                [cp * sp * vers, 1.0 + sp * sp * vers, sp * st],
                [-cp * st, -sp * st, ct],
            ]
        rot = jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)
        return rot, tangent

    def plane_rotation_jet(
        self, theta: Float[Array, "*p"], phi: Float[Array, ""], order: int
    ) -> tuple[Float[Array, "*p 3 3"], ...]:
        """The rotation at ``(theta, phi)`` and its partial derivatives up to ``order`` (1 or
        2): ``R, R_theta, R_phi``, then ``R_theta_theta, R_theta_phi, R_phi_phi``.

        ``R = B0(phi) + sin(theta) B1(phi) + (1 - cos theta) B2(phi)``
        (:meth:`rotation_basis`), so each derivative is three matrices per segment weighted by
        three numbers per point: a far smaller traced program than automatic derivatives of the
        nine matrix entries at every point. ``R`` itself is :meth:`plane_rotation_tangent`'s.
        """
        rot = self.plane_rotation_tangent(theta, phi)[0]
        basis = self.rotation_basis(phi, order)
        trig = _angle_coefficients(theta, order, self.sincos)

        def combine(n, m):  # d^n / d theta^n d^m / d phi^m, (n, m) != (0, 0)
            # Written out, not a reduction over the three matrices: one elementwise loop.
            sin_part, cos_part = trig[n]
            out = sin_part[..., None, None] * basis[m, 1] + cos_part[..., None, None] * basis[m, 2]
            return out + basis[m, 0] if n == 0 else out

        pairs = ((1, 0), (0, 1), (2, 0), (1, 1), (0, 2))
        return (rot, *(combine(n, m) for n, m in pairs[: (order + 1) * (order + 2) // 2 - 1]))

    def rotation_basis(self, phi: Float[Array, ""], order: int) -> Float[Array, "m 3 3 3"]:
        """``B[m, j]``: the ``m``-th derivative along ``phi`` (``m <= order``) of the matrix
        ``B_j`` of :meth:`plane_rotation_jet`."""
        sp, cp = self.sincos(phi)
        zero, one = jnp.zeros_like(cp), jnp.ones_like(cp)
        if self.frame == "paper":
            # Rz(phi) Ry(theta), with Ry(theta) = I + sin(theta) S + (1 - cos theta) S^2 and
            # S = [e_y]x; the m-th derivative of Rz(phi) turns its xy block by m quarter turns.
            xy = [(cp, -sp, sp, cp), (-sp, -cp, cp, -sp), (-cp, sp, -sp, -cp)]
            bases = []
            for m in range(order + 1):
                a, b, c, d = xy[m]
                corner = one if m == 0 else zero
                rz = _matrix([[a, b, zero], [c, d, zero], [zero, zero, corner]])
                # Rz S = (-Rz e_z, 0, Rz e_x) and Rz S^2 = -(Rz e_x, 0, Rz e_z), by columns.
                col_x, col_z, col_0 = rz[:, 0], rz[:, 2], jnp.zeros_like(rz[:, 0])
                rz_s = jnp.stack([-col_z, col_0, col_x], axis=-1)
                rz_s2 = jnp.stack([-col_x, col_0, -col_z], axis=-1)
                bases.append(jnp.stack([rz, rz_s, rz_s2]))
            return jnp.stack(bases)
        # Rz(phi) Ry(theta) Rz(-phi) = I + sin(theta) K + (1 - cos theta) K^2: the rotation by
        # theta about a = (-sin phi, cos phi, 0), K = [a]x, K^2 = a a^T - I.
        a = jnp.stack([-sp, cp, zero])
        da = jnp.stack([-cp, -sp, zero])
        eye = jnp.eye(3, dtype=cp.dtype)
        bases = [jnp.stack([eye, hat(a), jnp.outer(a, a) - eye])]
        if order >= 1:
            d_sq = jnp.outer(da, a) + jnp.outer(a, da)
            bases.append(jnp.stack([0.0 * eye, hat(da), d_sq]))
        if order >= 2:
            dd_sq = 2.0 * (jnp.outer(da, da) - jnp.outer(a, a))
            bases.append(jnp.stack([0.0 * eye, -hat(a), dd_sq]))
        return jnp.stack(bases)

    def strain(self, q, s):
        c = self._curvature(q, s)
        zero = jnp.zeros_like(c)
        if self.frame == "paper":
            # R = Rz(phi) Ry(alpha): bending about the (already twisted) local y axis.
            return jnp.stack([zero, c, zero])
        phi = q[-2]
        # R = Rz(phi) Ry(alpha) Rz(-phi): bending about the fixed axis (-sin phi, cos phi, 0).
        sp, cp = self.sincos(phi)
        return jnp.stack([-c * sp, c * cp, zero])

    def stiffness_scale(self, diagonal):
        # The force on the bending-plane angle is a bending moment times the curvature: scale
        # phi like c0, not by its (regularising) stiffness, or round-off in that force would be
        # amplified a million-fold in the scaled residual.
        return diagonal.at[:, -2].set(jnp.maximum(diagonal[:, -2], diagonal[:, 0]))

    def base_rotation(self, q):
        if self.frame == "paper":
            return rot_z(q[-2])
        return None

    def coordinate_energy(self, q, torsion_stiffness):
        k_phi = self.phi_stiffness_factor() * torsion_stiffness
        if self.frame == "paper":
            # The paper's 1/2 k_phi phi^2, k_phi = GJ / L: phi is a twist of the frame.
            return 0.5 * k_phi * q[-2] ** 2
        # A regulariser on the bending-plane angle: same curvature at phi = 0 as 1/2 k phi^2,
        # but periodic, so phi and phi + 2 pi stay the same configuration.
        return k_phi * (1.0 - self.sincos(q[-2])[1])


class PCC(PlanarCurvature):
    """Piecewise constant curvature: ``q_i = [c0, phi, dL]``.

    ``frame="torsion_free"`` (default) uses ``R = Rz(phi) Ry(alpha) Rz(-phi)``, which leaves a
    straight segment untwisted; ``frame="paper"`` uses the paper's ``R = Rz(phi) Ry(alpha)``,
    which twists the frame (and everything distal to it, tendon holes included) by ``phi``.
    ``phi_stiffness``: factor on ``GJ / L`` for the stiffness on ``phi`` (see
    :meth:`phi_stiffness_factor`).
    """

    def dofs_per_segment(self):
        return 3

    def coordinate_names(self):
        return ("c0", "phi", "dL")

    def _curvature(self, q, s):
        return q[0] * jnp.ones_like(s)

    def bending_angle(self, q, s):
        return q[0] * s

    def plane_angle_basis(self, s):
        return jnp.asarray(s)[..., None]


class PAC(PlanarCurvature):
    """Piecewise affine curvature (the paper): ``q_i = [c0, c1, phi, dL]``, ``c(s) = c0 + c1 s``.

    The polar coordinates force the curvature to stay in one plane per segment and make ``phi``
    undefined when ``c0 = c1 = 0``; :class:`PolynomialCurvature` with ``order=1`` is the
    Cartesian form of the same curvature law without that singularity (and lets the plane turn).
    See :class:`PCC` for ``frame``.
    """

    def dofs_per_segment(self):
        return 4

    def strain_degree(self):
        return 1

    def coordinate_names(self):
        return ("c0", "c1", "phi", "dL")

    def _curvature(self, q, s):
        return q[0] + q[1] * s

    def bending_angle(self, q, s):
        return s * (q[0] + 0.5 * q[1] * s)

    def plane_angle_basis(self, s):
        s = jnp.asarray(s)
        return jnp.stack([s, 0.5 * s * s], axis=-1)


class PolynomialCurvature(StrainModel):
    """Cartesian polynomial strain of order ``k``.

    ``q_i = [kx_0..kx_k, ky_0..ky_k, dL]``, plus ``tw_0..tw_k`` before ``dL`` when
    ``twist=True``; ``k_x(s) = sum_j kx_j s^j`` and likewise ``k_y`` and the twist. The bending
    plane may turn along the segment, and there is no angle coordinate, hence no singularity at
    the straight configuration. Prefer it to :class:`PAC` whenever the paper's exact
    parametrisation is not the point (fitting, inverse statics, buckling).
    """

    order: int = eqx.field(static=True, default=3)
    twist: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        if not isinstance(self.order, int) or self.order < 0:
            raise ValueError(
                f"PolynomialCurvature order must be an integer >= 0, got {self.order!r}"
            )

    def dofs_per_segment(self):
        return (3 if self.twist else 2) * (self.order + 1) + 1

    def coordinate_names(self):
        names = [f"kx_{j}" for j in range(self.order + 1)]
        names += [f"ky_{j}" for j in range(self.order + 1)]
        if self.twist:
            names += [f"tw_{j}" for j in range(self.order + 1)]
        return (*names, "dL")

    def has_twist_strain(self):
        return self.twist

    def strain_degree(self):
        return self.order

    def embedding(self, host):
        if not (
            isinstance(host, PolynomialCurvature)
            and host.twist == self.twist
            and host.order >= self.order
        ):
            return None
        blocks = 3 if self.twist else 2
        n, big = self.order + 1, host.order + 1
        return (
            *(b * big + j for b in range(blocks) for j in range(n)),
            host.dofs_per_segment() - 1,
        )

    def exact_rotation_substeps(self):
        # The bending plane may turn, so the Magnus series does not truncate: sub-step. Two
        # Gauss points per step integrate a cubic exactly; past that, halve the steps.
        if self.order == 0 and not self.twist:
            return 1
        return 4 if self.order <= 3 else 8

    def strain(self, q, s):
        n = self.order + 1
        # cumprod, not s ** arange: the derivative of s ** 0 is NaN at s = 0.
        powers = jnp.cumprod(jnp.concatenate([jnp.ones(1, q.dtype), jnp.full(n - 1, s, q.dtype)]))
        kx = jnp.dot(q[:n], powers, precision=MATMUL_PRECISION)
        ky = jnp.dot(q[n : 2 * n], powers, precision=MATMUL_PRECISION)
        tw = (
            jnp.dot(q[2 * n : 3 * n], powers, precision=MATMUL_PRECISION)
            if self.twist
            else jnp.zeros_like(kx)
        )
        return jnp.stack([-ky, kx, tw])


def common_family(models) -> tuple[StrainModel, tuple[StrainModel, ...]]:
    """``(host, members)``: the one model whose kinematics holds every model of ``models`` (see
    :meth:`StrainModel.embedding`), the highest order of their family, and the models as that
    family's members.

    Among polynomials a PCC segment (torsion-free frame) is ``PolynomialCurvature(0)``: the same
    kinematics (a constant strain vector) in Cartesian coordinates ``kx_0, ky_0``, without the
    polar plane angle. Raises a ValueError for models no one host holds (PAC among polynomials,
    whose plane is fixed along the segment; different frames or twist).
    """
    models = tuple(models)
    if any(isinstance(m, PolynomialCurvature) and not m.twist for m in models):
        models = tuple(
            PolynomialCurvature(0) if isinstance(m, PCC) and m.frame == "torsion_free" else m
            for m in models
        )
    for candidate in models:
        if all(m.embedding(candidate) is not None for m in models):
            return candidate, models
    raise ValueError(
        "Scene.model: segments may mix models of one family only, PCC with PAC (same frame "
        "and phi_stiffness) or PolynomialCurvature of different orders (same twist; a PCC "
        "segment among them is PolynomialCurvature(0)), got "
        f"{sorted({type(m).__name__ for m in models})}"
    )
