r"""Independent references for the rigid-body tests (no code of :mod:`fastvi.bodies`).

- :func:`top_reference`: a rigid body on a fixed point in ``(R, Ω)``, the rotation matrix
  and Euler's equations about the fixed point, integrated by SciPy's DOP853.
- :func:`open_chain_reference`: a chain of rigid bodies on revolute joints in joint
  coordinates (the product of exponentials; Kane's equations ``Nᵀ (M θ̈ + h) = 0``), with an
  optional cut joint closing a loop, whose constraint Jacobian may be rank deficient
  (Bricard's linkage): the accelerations are ``θ̈ = N ν + w`` with ``N`` the null space of
  the closure Jacobian and ``w`` its minimum-norm particular solution.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp


def _hat(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _rot(axis, angle):
    K = _hat(axis)
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * K @ K


def top_reference(mass, inertia, com, omega_body, g, t_eval, R0=None, rtol=1e-13):
    r"""``(R(t), Ω(t))`` of a body on a fixed point: ``Ṙ = R Ω̂``,
    ``J_O Ω̇ = (J_O Ω) × Ω + m X × (Rᵀ g)`` with ``J_O = J + m (|X|² 1 − X Xᵀ)``."""
    J = np.diag(inertia) if np.ndim(inertia) == 1 else np.asarray(inertia, float)
    X = np.asarray(com, float)
    gv = np.asarray(g, float)
    JO = J + mass * (X @ X * np.eye(3) - np.outer(X, X))
    R0 = np.eye(3) if R0 is None else np.asarray(R0, float)

    def rhs(t, y):
        R = y[:9].reshape(3, 3)
        W = y[9:]
        dW = np.linalg.solve(JO, np.cross(JO @ W, W) + mass * np.cross(X, R.T @ gv))
        return np.concatenate([(R @ _hat(W)).ravel(), dW])

    t_eval = np.asarray(t_eval, float)
    sol = solve_ivp(rhs, (0.0, t_eval[-1]), np.concatenate([R0.ravel(), omega_body]),
                    method="DOP853", rtol=rtol, atol=rtol, t_eval=t_eval)
    assert sol.success
    return sol.y[:9].T.reshape(-1, 3, 3), sol.y[9:].T


class OpenChain:
    r"""Rigid bodies ``k = 1 … K`` moved by revolute joints ``i = 0 … K−1`` about world axes
    ``s_i`` through ``p_i`` (at ``θ = 0``): body ``k`` by joints ``0 … k−1``. Each body has a
    mass, a world inertia tensor about its centre of mass at ``θ = 0`` and that centre.
    ``cut = (point, axis)``: the last body's point stays at ``point`` and its copy of ``axis``
    stays parallel to ``axis`` (a revolute joint to the ground closing the loop), leaving
    ``dof`` degrees of freedom."""

    def __init__(self, axes, points, masses, inertias, centres, gravity, cut=None, dof=None):
        self.s = [np.asarray(a, float) / np.linalg.norm(a) for a in axes]
        self.p = [np.asarray(x, float) for x in points]
        self.m = list(masses)
        self.I0 = [np.asarray(i, float) for i in inertias]
        self.c0 = [np.asarray(c, float) for c in centres]
        self.g = np.asarray(gravity, float)
        self.cut = cut
        self.K = len(self.m)
        self.dof = self.K if dof is None else int(dof)

    def _maps(self, th, dth):
        """The placement ``x -> R x + t`` of each body, and the current joint axes ``s_i``,
        points ``p_i``, their rates and the bodies' angular velocities. Joint ``i`` turns
        about its current axis: the new placement is ``Rot(s_i, θ_i)(R x + t − p_i) + p_i``."""
        R, trans, w = np.eye(3), np.zeros(3), np.zeros(3)
        pos, s, p, sd, pd, om = [], [], [], [], [], []
        for i in range(self.K):
            si = R @ self.s[i]
            pi = R @ self.p[i] + trans
            pd.append(sum((dth[l] * np.cross(s[l], pi - p[l]) for l in range(i)), np.zeros(3)))
            sd.append(np.cross(w, si))
            s.append(si)
            p.append(pi)
            Ri = _rot(si, th[i])
            trans = Ri @ (trans - pi) + pi
            R = Ri @ R
            w = w + dth[i] * si
            pos.append((R, trans))
            om.append(w)
        return pos, s, p, sd, pd, om

    def _point_terms(self, x, k, dth, s, p, sd, pd):
        """Jacobian (3, K) of a point of body ``k`` (1-based) and its bias acceleration."""
        J = np.zeros((3, self.K))
        for i in range(k):
            J[:, i] = np.cross(s[i], x - p[i])
        xd = J @ dth
        a = np.zeros(3)
        for i in range(k):
            a += dth[i] * (np.cross(sd[i], x - p[i]) + np.cross(s[i], xd - pd[i]))
        return J, a

    def positions(self, th):
        """Centres of mass (K, 3)."""
        pos = self._maps(th, np.zeros(self.K))[0]
        return np.array([R @ c + t for (R, t), c in zip(pos, self.c0)])

    def accelerations(self, th, dth):
        K = self.K
        pos, s, p, sd, pd, om = self._maps(th, dth)
        M = np.zeros((K, K))
        h = np.zeros(K)
        for k in range(1, K + 1):
            R, t = pos[k - 1]
            x = R @ self.c0[k - 1] + t
            Jv, av = self._point_terms(x, k, dth, s, p, sd, pd)
            Jw = np.zeros((3, K))
            aw = np.zeros(3)
            for i in range(k):
                Jw[:, i] = s[i]
                aw += dth[i] * sd[i]
            I = R @ self.I0[k - 1] @ R.T
            w = om[k - 1]
            M += self.m[k - 1] * Jv.T @ Jv + Jw.T @ I @ Jw
            h += self.m[k - 1] * Jv.T @ (av - self.g) + Jw.T @ (I @ aw + np.cross(w, I @ w))
        if self.cut is None:
            return np.linalg.solve(M, -h)
        point, axis = self.cut
        R, t = pos[-1]
        xe = R @ np.asarray(point, float) + t
        Jp, ap = self._point_terms(xe, K, dth, s, p, sd, pd)
        a = R @ (np.asarray(axis, float) / np.linalg.norm(axis))
        w = om[-1]
        aw = sum((dth[i] * sd[i] for i in range(K)), np.zeros(3))
        e = [v for v in np.eye(3) if abs(v @ a) < 0.5]  # the two directions ⟂ the axis
        Ja = np.array([[ei @ np.cross(s[i], a) for i in range(K)] for ei in e])
        ba = np.array([ei @ (np.cross(aw, a) + np.cross(w, np.cross(w, a))) for ei in e])
        C = np.vstack([Jp, Ja])
        bias = np.concatenate([ap, ba])
        # the mobility is known (``dof``): off the closure by round-off, C's small singular
        # values are not zero, and a tolerance would flip its rank
        U, S, Vt = np.linalg.svd(C)
        rank = self.K - self.dof
        N = Vt[rank:].T
        wpart = -Vt[:rank].T @ ((U[:, :rank].T @ bias) / S[:rank])
        nu = np.linalg.solve(N.T @ M @ N, -N.T @ (M @ wpart + h))
        return N @ nu + wpart


def open_chain_reference(chain: OpenChain, th0, dth0, t_eval, rtol=1e-12):
    """Joint angles (T, K) and centres of mass (T, K, 3) at ``t_eval`` (DOP853)."""
    K = chain.K

    def rhs(t, y):
        return np.concatenate([y[K:], chain.accelerations(y[:K], y[K:])])

    t_eval = np.asarray(t_eval, float)
    sol = solve_ivp(rhs, (0.0, t_eval[-1]), np.concatenate([th0, dth0]), method="DOP853",
                    rtol=rtol, atol=rtol, t_eval=t_eval)
    assert sol.success, sol.message
    th = sol.y[:K].T
    return th, np.array([chain.positions(x) for x in th])
