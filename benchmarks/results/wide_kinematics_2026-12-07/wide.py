"""Prototype: PAC (torsion-free) body inertia M, C qdot with structure-of-arrays kinematics:
every 3x3 as nine arrays, every vector as three, so XLA fuses the kinematics into few loops."""
import os
MODE = os.environ.get('MODE', 'reduce')
BAR = os.environ.get('BAR', '') == '1'
BAR2 = os.environ.get('BAR2', '') == '1'
ASSEMBLY = os.environ.get('ASSEMBLY', 'stack')
import numpy as np, jax, jax.numpy as jnp
from pacjax._model.quadrature import gauss_legendre


def mm(A, B):
    return [[sum(A[i][k] * B[k][j] for k in range(3)) for j in range(3)] for i in range(3)]

def mv(A, x):
    return [sum(A[i][k] * x[k] for k in range(3)) for i in range(3)]

def mtv(A, x):
    return [sum(A[k][i] * x[k] for k in range(3)) for i in range(3)]

def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]

def vee_mtm(A, B):
    """vee of skew part of A^T B."""
    C = lambda i, j: sum(A[k][i] * B[k][j] for k in range(3))
    return [0.5 * (C(2, 1) - C(1, 2)), 0.5 * (C(0, 2) - C(2, 0)), 0.5 * (C(1, 0) - C(0, 1))]

def vee_mmt(A, B):
    """vee of skew part of A B^T."""
    C = lambda i, j: sum(A[i][k] * B[j][k] for k in range(3))
    return [0.5 * (C(2, 1) - C(1, 2)), 0.5 * (C(0, 2) - C(2, 0)), 0.5 * (C(1, 0) - C(0, 1))]


class Wide:
    def __init__(self, scene, lumped, phi_extra, dtype=jnp.float64):
        knots = lumped.knots
        self.sk = jnp.asarray(knots.s, dtype)  # (n, W)
        self.sn = jnp.asarray(knots.node_s, dtype)  # (n, W-1, G)
        nodes, weights = gauss_legendre(knots.interval_nodes)
        h = np.diff(knots.s, axis=1)
        hw = h[:, :, None] * np.asarray(weights)[None, None, :]  # (n, W-1, G)
        self.hw = jnp.asarray(hw, dtype)
        W = knots.s.shape[1]
        self.tri = jnp.asarray(np.arange(W)[:, None] > np.arange(W - 1)[None, :], dtype)  # (W, W-1)
        self.L = scene.robot.stacked("length").astype(dtype)[:, None]
        self.B0 = np.asarray(scene.robot.base_rotation, float).tolist()
        self.P0 = np.asarray(scene.robot.base_position, float).tolist()
        n = knots.s.shape[0]
        self.n, self.W = n, W
        self.m = lumped.masses.reshape(n, W)
        self.I = [lumped.moments[:, c].reshape(n, W) for c in range(3)]
        self.phi_extra = phi_extra

    def local(self, c):
        """c: (n, 4) coordinates -> local R (9 arrays (n, W)), p (3 arrays (n, W))."""
        c0, c1, phi, dl = (c[:, i:i + 1] for i in range(4))
        sk = self.sk
        th = sk * (c0 + 0.5 * c1 * sk)
        st, ct = jnp.sin(th), jnp.cos(th)
        vt = 2.0 * jnp.sin(0.5 * th) ** 2
        sp, cp = jnp.sin(phi), jnp.cos(phi)
        if BAR:
            st, ct, vt, sp, cp = jax.lax.optimization_barrier((st, ct, vt, sp, cp))
        R = [[1.0 - vt * cp * cp, -vt * cp * sp, st * cp],
             [-vt * cp * sp, 1.0 - vt * sp * sp, st * sp],
             [-st * cp, -st * sp, ct]]
        sn = self.sn
        thn = sn * (c0[..., None] + 0.5 * c1[..., None] * sn)
        X = jnp.sum(self.hw * jnp.sin(thn), axis=-1)  # (n, W-1)
        Z = jnp.sum(self.hw * jnp.cos(thn), axis=-1)
        if BAR:
            X, Z = jax.lax.optimization_barrier((X, Z))
        if MODE == "cumsum":
            XZ = jnp.cumsum(jnp.stack([X, Z]), axis=-1)
            XZ = jnp.concatenate([jnp.zeros_like(XZ[..., :1]), XZ], axis=-1)
            Xk, Zk = XZ[0], XZ[1]
        elif MODE == "dot":
            XZ = jnp.matmul(jnp.stack([X, Z]), self.tri.T)
            Xk, Zk = XZ[0], XZ[1]
        else:
            Xk = jnp.sum(self.tri * X[:, None, :], axis=-1)  # (n, W)
            Zk = jnp.sum(self.tri * Z[:, None, :], axis=-1)
        ell = self.L + dl
        p = [ell * cp * Xk, ell * sp * Xk, ell * Zk]
        return R, p

    def chain(self, R, p):
        """Bases of each segment (9 + 3 arrays of shape (n, 1))."""
        B, P = self.B0, self.P0
        Bs, Ps = [B], [P]
        for i in range(self.n - 1):
            E = [[R[a][b][i, -1] for b in range(3)] for a in range(3)]
            e = [p[a][i, -1] for a in range(3)]
            P = [P[a] + sum(B[a][k] * e[k] for k in range(3)) for a in range(3)]
            B = mm(B, E)
            Bs.append(B); Ps.append(P)
        st = lambda xs: jnp.stack([jnp.asarray(x, R[0][0].dtype) for x in xs])[:, None]
        return ([[st([Bi[a][b] for Bi in Bs]) for b in range(3)] for a in range(3)],
                [st([Pi[a] for Pi in Ps]) for a in range(3)])

    def world(self, q):
        c = q.reshape(self.n, 4)
        R, p = self.local(c)
        B, P = self.chain(R, p)
        Rw = mm(B, R)
        pw = [P[a] + sum(B[a][k] * p[k] for k in range(3)) for a in range(3)]
        return Rw, pw, (R, p, B)

    def dynamics(self, q, qd):
        n, W = self.n, self.W
        c = q.reshape(n, 4)
        eye4 = jnp.eye(4, dtype=q.dtype)
        # Local derivatives along each segment's own 4 coordinates: (4, n, W) arrays.
        R, p = self.local(c)
        dR, dp = jax.vmap(lambda t: jax.jvp(self.local, (c,), (jnp.broadcast_to(t, c.shape),))[1])(eye4)
        if BAR2:
            R, p, dR, dp = jax.lax.optimization_barrier((R, p, dR, dp))
        B, P = self.chain(R, p)
        Rw = mm(B, R)
        pw = [P[a] + sum(B[a][k] * p[k] for k in range(3)) for a in range(3)]
        if BAR2:
            B, P, Rw, pw = jax.lax.optimization_barrier((B, P, Rw, pw))
        own_pos = mv(B, dp)  # world, (4, n, W)
        own_ang = vee_mtm(R, dR)  # body
        E = [[R[a][b][:, -1:] for b in range(3)] for a in range(3)]  # (n, 1)
        dE = [[dR[a][b][:, :, -1:] for b in range(3)] for a in range(3)]  # (4, n, 1)
        end_ang = mv(B, vee_mmt(dE, E))  # world, (4, n(j), 1)
        end_lin = [x[:, :, -1:] for x in own_pos]  # (4, n(j), 1)
        # far[i, p, j, k]: arrays (n_i, W, n_j, 4)
        T = lambda x: jnp.transpose(x[..., 0], (1, 0))[None, None]  # (4, n_j, 1) -> (1, 1, n_j, 4)
        wa = [T(x) for x in end_ang]
        el = [T(x) for x in end_lin]
        lever = [pw[a][:, :, None, None] - pw[a][:, -1][None, None, :, None] for a in range(3)]
        far_pos = [x + y for x, y in zip(cross(wa, lever), el)]
        Rw4 = [[Rw[a][b][:, :, None, None] for b in range(3)] for a in range(3)]
        far_ang = mtv(Rw4, wa)
        rows = np.arange(n)
        beyond = jnp.asarray(rows[:, None] > rows[None, :], q.dtype)[:, None, :, None]
        same = jnp.asarray(np.eye(n), q.dtype)[:, None, :, None]
        own4 = lambda x: jnp.transpose(x, (1, 2, 0))[:, :, None, :]  # (4, n, W) -> (n, W, 1, 4)
        m = self.m.reshape(-1)
        def vel(x):
            (Rw_, pw_, _), (dRw, dpw, _) = jax.jvp(self.world, (x,), (qd,))
            return pw_, vee_mtm(Rw_, dRw), dpw
        (_, omega, v), (_, alpha, acc) = jax.jvp(vel, (q,), (qd,))
        if ASSEMBLY == "stack":
            Jp = jnp.stack([beyond * f + same * own4(o) for f, o in zip(far_pos, own_pos)]).reshape(3, n * W, n * 4)
            Ja = jnp.stack([beyond * f + same * own4(o) for f, o in zip(far_ang, own_ang)]).reshape(3, n * W, n * 4)
            if BAR2:
                omega, alpha, acc, Jp, Ja = jax.lax.optimization_barrier((omega, alpha, acc, Jp, Ja))
            Im = jnp.stack([x.reshape(-1) for x in self.I])
            omega = jnp.stack([x.reshape(-1) for x in omega]); alpha = jnp.stack([x.reshape(-1) for x in alpha])
            acc = jnp.stack([x.reshape(-1) for x in acc])
            euler = Im * alpha + jnp.stack(cross(list(omega), list(Im * omega)))
            mat = jnp.einsum("cpi,p,cpj->ij", Jp, m, Jp) + jnp.einsum("cpi,cp,cpj->ij", Ja, Im, Ja)
            bias = jnp.einsum("cpi,p,cp->i", Jp, m, acc) + jnp.einsum("cpi,cp->i", Ja, euler)
        else:  # one array per component, no stacks
            Jp = [(beyond * f + same * own4(o)).reshape(n * W, n * 4) for f, o in zip(far_pos, own_pos)]
            Ja = [(beyond * f + same * own4(o)).reshape(n * W, n * 4) for f, o in zip(far_ang, own_ang)]
            if BAR2:
                omega, alpha, acc, Jp, Ja = jax.lax.optimization_barrier((omega, alpha, acc, Jp, Ja))
            Im = [x.reshape(-1) for x in self.I]
            omega = [x.reshape(-1) for x in omega]; alpha = [x.reshape(-1) for x in alpha]
            acc = [x.reshape(-1) for x in acc]
            Iw = [a * b for a, b in zip(Im, omega)]
            euler = [a * b + c for a, b, c in zip(Im, alpha, cross(omega, Iw))]
            mat = sum(jnp.einsum("pi,p,pj->ij", Jp[c], m, Jp[c]) + jnp.einsum("pi,p,pj->ij", Ja[c], Im[c], Ja[c]) for c in range(3))
            bias = sum(jnp.einsum("pi,p->i", Jp[c], m * acc[c]) + jnp.einsum("pi,p->i", Ja[c], euler[c]) for c in range(3))
        mat = mat + jnp.diag(self.phi_extra)
        return 0.5 * (mat + mat.T), bias
