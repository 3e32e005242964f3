"""The equilibrium problem in scaled coordinates: residual, merit, linearisation and the
continuation's moves on the bending vector."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool

from .._config import MATMUL_PRECISION
from .._model.hessian import dead_followers, energy_derivatives, follower_jacobian
from .._model.scene import Scene, SceneConstants

#: Smallest end angle (rad) of a segment whose Newton model follows the moves
#: (:meth:`ScaledProblem.move_curvature`): the plane angle's regulariser (1e-6 of the elastic
#: scale) divided by it stays 1e-3 of that scale.
_MOVE_CURVATURE_THETA = 1e-3
#: Scaled residual below which the solver's Jacobian is the energy's Hessian again.
_MOVE_CURVATURE_RESIDUAL = 1e-3


def _round_off(dtype) -> float:
    """Curvature coordinates within this of zero are straight to round-off (their scale is 1)."""
    return 1e3 * float(jnp.finfo(dtype).eps)


def _singular_bends(theta, c, beta) -> Bool[Array, " n"]:
    """Per segment, whether the moves of :meth:`ScaledProblem.moved` are singular: the end
    angle ``theta = c . beta`` below :data:`_MOVE_CURVATURE_THETA`, or below half of
    ``sum |beta_j c_j|`` (an S of PAC, whose end is turned by little of what it bends)."""
    spread = jnp.matmul(jnp.abs(c), jnp.abs(beta), precision=MATMUL_PRECISION)
    return (jnp.abs(theta) < _MOVE_CURVATURE_THETA) | (jnp.abs(theta) < 0.5 * spread)


class ScaledProblem(eqx.Module):
    """The equilibrium problem in scaled coordinates ``y = q / sigma``.

    The residual ``r(y) = F(sigma y) / (d sigma)`` is dimensionless (``d`` the diagonal of the
    elastic stiffness); ``D = diag(d)`` is the damping of the flow.
    """

    scene: Scene
    controls: jax.Array
    sigma: jax.Array
    row: jax.Array
    consts: SceneConstants
    # Follower forces as dead ones (``pacjax._model.hessian.dead_followers``), for the Jacobian.
    dead_scene: Scene | None = None
    dead_consts: SceneConstants | None = None
    dead_index: tuple[int, ...] = eqx.field(static=True, default=())

    @staticmethod
    def build(scene: Scene, controls: jax.Array) -> "ScaledProblem":
        """The scaled problem; the scene's parameter-only terms are computed here, once, not
        in every energy evaluation of the solver loop (they stay differentiable)."""
        dtype = controls.dtype
        sigma = jax.lax.stop_gradient(scene.coordinate_scale(dtype))
        d = jax.lax.stop_gradient(scene.elastic_stiffness_diagonal(dtype))
        dead = None if scene.is_conservative else dead_followers(scene)
        dead_scene, index = (None, ()) if dead is None else dead
        dead_consts = None if dead is None else dead_scene.constants(dtype)
        return ScaledProblem(
            scene,
            controls,
            sigma,
            1.0 / (d * sigma),
            scene.constants(dtype),
            dead_scene,
            dead_consts,
            index,
        )

    def q(self, y):
        return self.sigma * y

    def residual(self, y):
        return self.scene.residual(self.q(y), self.controls, self.consts) * self.row

    def residual_and_merit(self, y):
        """Scaled residual and the potential energy of the conservative part (J), the merit
        of the continuation (with the non-conservative forces frozen, see :meth:`drive`)."""
        q = self.q(y)
        energy, grad = jax.value_and_grad(self.scene.potential_energy)(
            q, self.controls, self.consts
        )
        if not self.scene.is_conservative:
            grad = grad - self.scene.nonconservative_forces(q)
        return grad * self.row, energy

    def drive(self, y):
        """Non-conservative generalised forces in scaled coordinates: ``r = dE/dy - drive``
        up to the row scale (``frozen_work`` of :class:`PseudoTransientContinuation`)."""
        return self.sigma * self.scene.nonconservative_forces(self.q(y))

    def energy(self, y):
        """Potential energy (J) at ``y``: the merit of a conservative scene, without its
        gradient."""
        return self.scene.potential_energy(self.q(y), self.controls, self.consts)

    def linearise(self, y):
        """Scaled residual and its Jacobian, ``(dr/dy, (r, (merit, weights)))``, from the
        structured Hessian of the potential energy. Follower forces of a PCC/PAC scene enter
        it as dead forces plus the turning of their direction
        (:func:`pacjax._model.hessian.follower_jacobian`; the residual is
        :meth:`residual_and_merit`'s).
        Other non-conservative scenes add the forward derivative of their non-conservative
        loads alone (a few points of the kinematics), not of the whole residual, which is
        cheaper. A conservative scene's Hessian is that of the energy along the continuation's
        moves (:meth:`move_curvature`)."""
        q = self.q(y)
        if self.dead_scene is not None:
            hessian = follower_jacobian(
                self.scene, self.dead_scene, self.dead_index, q, self.controls, self.dead_consts
            )
            r, energy = self.residual_and_merit(y)
            jac = self.row[:, None] * hessian * self.sigma[None, :]
            return jac, (r, (energy, self.weights()))
        energy, grad, hessian = energy_derivatives(self.scene, q, self.controls, self.consts)
        merit = energy
        if self.scene.is_conservative:
            # Near a solution Newton's steps converge with either model, and the solver's
            # last Jacobian is the energy's (for the derivatives and the stability check).
            polar = self.polar_model(grad * self.row)
            hessian = hessian + jnp.where(polar, 0.0, self.move_curvature(q, grad))
        else:

            def forces(x):
                value = self.scene.nonconservative_forces(x)
                return value, value

            d_forces, value = jax.jacfwd(forces, has_aux=True)(q)
            grad, hessian = grad - value, hessian - d_forces
        jac = self.row[:, None] * hessian * self.sigma[None, :]
        return jac, (grad * self.row, (merit, self.weights()))

    def polar_model(self, r) -> Bool[Array, ""]:
        """Whether the Jacobian that :meth:`linearise` gives where the scaled residual is ``r``
        is the Hessian of the energy in the coordinates themselves, not along :meth:`moved`'s
        moves: always where there are no moves, else near a solution of a conservative scene
        (``_MOVE_CURVATURE_RESIDUAL``). There its Newton step is ``y + dy``."""
        if self.scene.model.free_plane_angle() is None:
            return jnp.asarray(True)
        if not self.scene.is_conservative:
            return jnp.asarray(False)
        return jnp.max(jnp.abs(r)) <= _MOVE_CURVATURE_RESIDUAL

    def moved(self, y, dy):
        """The iterate after the continuation step ``dy`` from ``y``: ``y + dy``, except for the
        bending of a PCC/PAC segment whose plane angle ``phi`` is free (torsion-free frame) and
        whose end is turned (``theta = beta . c != 0``, the bending angle at its end).

        There the curvatures ``c`` and ``phi`` are polar coordinates. A tendon's length in the
        segment, ``-r theta cos(phi - alpha)`` up to the chords, is linear in the bending vector
        ``B = theta e(phi)`` (``e(phi)`` the plane's direction) and bilinear in ``(c, phi)``, so
        steps along ``phi`` crept (3-4 steps for the plane's turn on the paper's robot). The
        step is taken on ``B``: ``B' = B + dtheta e(phi) + theta dphi e'(phi)``, the plane
        turned to ``B'`` by less than a quarter turn (a bend that passes through straight goes
        on with ``theta < 0``), and every curvature carried along as a vector in the plane,
        ``c' = (c + dc) cos(turn) + c dphi sin(turn)``, so that ``theta' e(phi') = B'``. This
        agrees with ``y + dy`` to first order: the step's descent and the search along it are
        unchanged, and the plane's turn no longer creeps (``benchmarks/RESULTS.md``, "Figures
        behind the solver's settings"). The step is ``y + dy`` for a segment straight to
        round-off (``|theta|`` within ``1000 eps`` of zero, as in :meth:`aligned`) and, in a
        conservative scene, wherever the moves are singular (:func:`_singular_bends`: an end
        turned by little, an S of PAC), where the Newton model is the polar Hessian
        (:meth:`move_curvature`).
        """
        k = self.scene.model.free_plane_angle()
        if k is None:
            return y + dy
        q = self.scene.coordinates(self.sigma * y)
        dq = self.scene.coordinates(self.sigma * dy)
        beta = self.scene.model.plane_angle_basis(jnp.ones((), y.dtype))
        c, dc, dphi = q[:, :k], dq[:, :k], dq[:, k]
        theta = jnp.matmul(c, beta, precision=MATMUL_PRECISION)
        ahead = theta + jnp.matmul(dc, beta, precision=MATMUL_PRECISION)
        # The angle of B' from e(phi), in (-pi/2, pi/2]: arctan(theta dphi / (theta + dtheta)).
        turn = jnp.arctan2(theta * dphi * jnp.where(ahead < 0, -1.0, 1.0), jnp.abs(ahead))
        c_new = (c + dc) * jnp.cos(turn)[:, None] + c * (dphi * jnp.sin(turn))[:, None]
        # A conservative scene's Newton model follows the moves except where they are singular
        # (move_curvature); there the step is polar too: at an end turned by little, or by
        # little of what an S of PAC bends it, B' turns the plane by theta dphi / (theta +
        # dtheta), a fraction of dphi that the model does not know, and the search found no
        # descent along it. (A non-conservative scene's model is always polar, and the moves
        # are what lead its follower rows off an indefinite attractor: tests/test_ptc.py.) A
        # bend at round-off is no bend in any scene: its B' would turn the plane by a random
        # fraction of dphi.
        flat = jnp.abs(theta) <= _round_off(y.dtype)
        if self.scene.is_conservative:
            flat = flat | _singular_bends(theta, c, beta)
        c_new = jnp.where(flat[:, None], c + dc, c_new)
        turn = jnp.where(flat, dphi, turn)
        q_new = (q + dq).at[:, :k].set(c_new).at[:, k].set(q[:, k] + turn)
        return self.scene.free_part(q_new) / self.sigma

    def move_curvature(self, q, grad):
        """``sum_i grad_i d2 m_i / d dq2`` at ``dq = 0``, ``m(dq)`` the coordinates that
        :meth:`moved` reaches from ``q``: added to the Hessian, it makes the Newton model that
        of the energy along the moves, ``E(m(dq))``, rather than along straight lines in the
        polar coordinates (zero for other models).

        Along the moves the bending vector ``B = theta e(phi)`` is affine in the step, so a
        load linear in ``B`` (a tendon's length, up to the chords) has a quadratic energy and
        its Newton step lands on the solution; the polar Hessian's cross term
        ``d2E / dc dphi`` and its ``d2E / dphi2`` (a force times the curvature) instead send
        the plane past it. From :meth:`moved` to second order, per segment: ``d2 c_j / dphi2 =
        c_j`` and ``d2 phi / dphi dc_j = -beta_j / theta``. Where the end angle ``theta`` is
        small (below :data:`_MOVE_CURVATURE_THETA`: the plane angle's regulariser force over
        ``theta`` would dominate) or mostly cancelled (an S of PAC: ``|theta|`` below half of
        ``sum |beta_j c_j|``) the moves themselves are singular and the polar Hessian is kept.
        """
        k = self.scene.model.free_plane_angle()
        if k is None:
            return jnp.zeros((q.shape[0], q.shape[0]), q.dtype)
        n, d = self.scene.n_segments, self.scene.dofs_per_segment
        coords, force = self.scene.coordinates(q), self.scene.coordinates(grad)
        beta = self.scene.model.plane_angle_basis(jnp.ones((), q.dtype))
        c = coords[:, :k]
        theta = jnp.matmul(c, beta, precision=MATMUL_PRECISION)
        singular = _singular_bends(theta, c, beta)
        along_phi = jnp.where(singular, 0.0, jnp.sum(force[:, :k] * c, axis=1))
        turn = jnp.where(singular, 0.0, -force[:, k] / jnp.where(singular, 1.0, theta))
        cross = (turn[:, None] * beta[None, :]).reshape(-1)
        # Each segment's block: its angle's row and column (indices of the full layout).
        angle = np.arange(n) * d + k
        curvature = (angle[:, None] - k + np.arange(k)[None, :]).reshape(-1)
        beside = np.repeat(angle, k)
        full = (
            jnp.zeros((n * d, n * d), q.dtype)
            .at[angle, angle]
            .set(along_phi)
            .at[beside, curvature]
            .set(cross)
            .at[curvature, beside]
            .set(cross)
        )
        free = self.scene.free_coordinates()
        return full if free is None else full[free][:, free]

    def aligned(self, y, tol: float, keep=None):
        """``y`` with the bending plane of each straight segment turned to the force on it.

        A PCC/PAC segment's bending-plane angle ``phi`` is undefined while it is straight (the
        shape does not depend on it), so a straight start is a degenerate saddle: the
        continuation first bends the segments in whatever plane ``phi`` says and then turns the
        planes, with an indefinite stiffness all the while, which costs steps. At zero
        curvature the force on ``c0`` is exactly ``a cos(phi) + b sin(phi)``, since it is
        linear in the bending direction ``(cos(phi), sin(phi))``: the residuals at ``phi = 0``
        and ``pi / 2`` give the plane of steepest descent. ``phi`` is taken in
        ``(-pi/2, pi/2]``, the half that the regulariser ``k (1 - cos(phi))`` prefers; the sign
        of ``c0`` then picks the side. A segment that is bent keeps its ``phi``, and so does one
        where ``keep`` (a boolean per segment) says so. A straight segment whose force is below
        ``tol`` (scaled) takes the plane of the segment before it (the first segment keeps its
        ``phi``). Straight: every scaled curvature coordinate within ``1000 eps`` of zero.
        """
        k = self.scene.model.free_plane_angle()
        if k is None:
            return y
        n = self.scene.n_segments
        coords = self.scene.coordinates(y)
        # Straight to round-off, not only exactly: an equilibrium solved from a straight start
        # comes back with curvatures of 1e-18, and a plane kept there is the same saddle.
        round_off = _round_off(y.dtype)
        straight = jnp.all(jnp.abs(coords[:, :k]) <= round_off, axis=1)
        if keep is not None:
            straight = straight & ~keep

        def force_on_c0(phi):
            trial = coords.at[:, k].set(jnp.where(straight, phi, coords[:, k]))
            return self.scene.coordinates(self.residual(self.scene.free_part(trial)))[:, 0]

        # One batched residual (one copy of its graph to compile).
        a, b = jax.vmap(force_on_c0)(jnp.asarray([0.0, 0.5 * np.pi], y.dtype))
        phi = jnp.arctan2(-b, -a)
        phi = jnp.where(phi > 0.5 * np.pi, phi - np.pi, phi)
        phi = jnp.where(phi <= -0.5 * np.pi, phi + np.pi, phi)
        turn = straight & (jnp.hypot(a, b) > tol) & jnp.isfinite(phi)
        phi = jnp.where(turn, phi, coords[:, k])
        # A straight segment with no force on it is loaded only through the segments before
        # it, which bend in their own planes: it takes its predecessor's plane. (Kept at its
        # phi, it meets a saddle in that plane.)
        inherit = straight & ~turn
        for i in range(1, n):
            phi = phi.at[i].set(jnp.where(inherit[i], phi[i - 1], phi[i]))
        return self.scene.free_part(coords.at[:, k].set(phi))

    def weights(self):
        """``sqrt(d) sigma``: maps scaled coordinates to ``D^1/2``-weighted ones."""
        return jnp.sqrt(self.sigma / self.row)

    @staticmethod
    def root_fn(y, args: "ScaledProblem"):
        """``(r, (merit, weights))`` for :class:`PseudoTransientContinuation`."""
        r, merit = args.residual_and_merit(y)
        return r, (merit, args.weights())


@eqx.filter_jit
def flow_field(t, y, problem: ScaledProblem):
    """``-r(y)``, jitted on its own so that the solver's calls and derivatives share one trace
    (the problem comes in diffrax's ``args``)."""
    return -problem.residual(y)
