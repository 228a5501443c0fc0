r"""Yardstick: the step kernel hand-specialized to the Cartesian double pendulum.

The generic kernel (``fastvi/kernels/step.py``) evaluates the model through ``numba.cfunc``
callbacks whose sizes it learns at run time. This module runs the *same algorithm* with the
double pendulum written directly into the assembly, so that the ratio of the two run times
measures what the generic model interface costs (opaque callbacks, sizes known only at run
time, dense handling of ``M``, ``∇²V``, ``G`` and ``∇²g``) and nothing else:

* same unknowns ``X = (ΔQ^1 … ΔQ^s, η_0 … η_{J−1})`` and residual rows, same predictor
  (the last two steps' Hermite polynomial extrapolated with ``E2`` where it agrees with the last
  step's, extrapolated with ``E``), same Newton stopping rule and tolerance (increment
  scaled by ``max(1, |q_k|)``, contraction estimate, round-off plateau), the same
  divergence exit and retries from guesses of lower degree when Newton fails, same final residual
  pass, same LU (:mod:`fastvi.kernels.linalg`) for the Newton matrix and
  for ``G M⁻¹ Gᵀ``, same RATTLE end-momentum projection, same diagnostics per step
  (``max|g(q1)|``, ``max|G v1|``, Newton iterations, energy) saved at every step;
* the model is inlined (``n = 4``, ``m = 2`` are compile-time constants). With
  ``q = (x1, y1, x2, y2)`` and ``params = (m1, m2, l1, l2, g)``:

      M = diag(m1, m1, m2, m2)                       (constant: ``M⁻¹`` is a division)
      ∇V = (0, g m1, 0, g m2),   ∇²V = 0             (constant: ``q(c_i)`` is never needed)
      g1 = ½(x1² + y1² − l1²),   g2 = ½(Δx² + Δy² − l2²),   Δ = (x2 − x1, y2 − y1)
      G  = [[x1, y1, 0, 0], [−Δx, −Δy, Δx, Δy]]
      Σ_a η_a ∇²g_a = (η1+η2)(e11 + e22) + η2(e33 + e44 − e13 − e31 − e24 − e42)

  only the non-zero entries of ``M``, ``G`` and the constraint Hessian are touched.

Floating-point operations are kept in the generic kernel's order wherever they touch a
non-zero value, so the trajectory matches ``fastvi.integrate`` to round-off
(``tests/test_yardstick.py``). The method tables arrive as arrays, so one compiled kernel
serves every ``PsL-QrG`` method.
"""

from __future__ import annotations

import time

import numpy as np

from fastvi._numba import hot, njit
from fastvi.kernels.linalg import lu_factor, lu_solve
from fastvi.kernels.step import extrapolate
from fastvi.status import Status

#: numba caches these kernels keyed on fastvi's sources too (fastvi._numba): they compile
#: fastvi.kernels.linalg into themselves, and numba alone would watch only this file
FASTVI_CACHE_STAMP = True

# n and m of the double pendulum, read by numba as compile-time constants
NQ = 4
NC = 2

# fastvi's status codes, as the generic kernel uses them
from fastvi.kernels.layout import NEWTON_FAILED as NEWTON  # noqa: E402
from fastvi.kernels.layout import NONFINITE, OK, SINGULAR  # noqa: E402
from fastvi.kernels.layout import SINGULAR_CONSTRAINTS as SING_CONS  # noqa: E402


@hot
def _constraint_point(prm, qd, gj, Gj):
    """g(qd) into ``gj`` and the non-zero entries of G(qd) into ``Gj`` (its zeros stay 0)."""
    dx = qd[2] - qd[0]
    dy = qd[3] - qd[1]
    l1 = prm[2]
    l2 = prm[3]
    gj[0] = 0.5 * (qd[0] * qd[0] + qd[1] * qd[1] - l1 * l1)
    gj[1] = 0.5 * (dx * dx + dy * dy - l2 * l2)
    Gj[0, 0] = qd[0]
    Gj[0, 1] = qd[1]
    Gj[1, 0] = -dx
    Gj[1, 1] = -dy
    Gj[1, 2] = dx
    Gj[1, 3] = dy


@hot
def assemble(prm, tabs, h, qk, pk, X, R, A, D, G, qd, gj, jac):
    """Residual (and, if ``jac``, the Newton matrix) at ``X``; the double pendulum inlined.

    Mirrors ``fastvi.kernels.step.residual`` and ``newton_matrix`` row for row: the mass
    part of ``D`` from the quadratic form ``Am``, the potential's from ``bL`` (M and ∇V are
    constant, so no quadrature point is visited). Returns 0 or ``NONFINITE``.
    """
    Lc, Am, bL = tabs.Lc, tabs.Am, tabs.bL
    m1 = prm[0]
    m2 = prm[1]
    grav = prm[4]
    s = tabs.L.shape[0] - 1
    J = Lc.shape[1] - 1
    sn = s * NQ
    N = sn + J * NC
    inv_h = 1.0 / h
    # −∇V, constant
    f1 = -(grav * m1)
    f3 = -(grav * m2)
    mass = (m1, m1, m2, m2)

    for a in range(NQ):
        d0 = 0.0
        for nu in range(1, s + 1):
            acc = 0.0
            for mu in range(s):
                acc += Am[nu - 1, mu] * X[mu * NQ + a]
            acc *= inv_h
            acc *= mass[a]
            D[nu, a] = acc
            d0 -= acc
        D[0, a] = d0
    for nu in range(s + 1):
        w = h * bL[nu]
        D[nu, 0] += w * 0.0
        D[nu, 1] += w * f1
        D[nu, 2] += w * 0.0
        D[nu, 3] += w * f3
    for a in range(NQ):
        R[a] = pk[a] + D[0, a]
    for nu in range(1, s):
        for a in range(NQ):
            R[nu * NQ + a] = D[nu, a]

    for j in range(1, J + 1):
        for a in range(NQ):
            qa = qk[a]
            for nu in range(1, s + 1):
                cl = Lc[nu, j]
                if cl != 0.0:
                    qa += cl * X[(nu - 1) * NQ + a]
            qd[a] = qa
        _constraint_point(prm, qd, gj, G[j])
        row = sn + (j - 1) * NC
        R[row] = gj[0]
        R[row + 1] = gj[1]
    for j in range(J):
        Gj = G[j]
        col = sn + j * NC
        for nu in range(s):
            cl = Lc[nu, j]
            if cl == 0.0:
                continue
            r0 = nu * NQ
            e0 = cl * X[col]
            e1 = cl * X[col + 1]
            R[r0] -= Gj[0, 0] * e0
            R[r0 + 1] -= Gj[0, 1] * e0
            R[r0] -= Gj[1, 0] * e1
            R[r0 + 1] -= Gj[1, 1] * e1
            R[r0 + 2] -= Gj[1, 2] * e1
            R[r0 + 3] -= Gj[1, 3] * e1
    for k in range(N):
        if not np.isfinite(R[k]):
            return NONFINITE
    if not jac:
        return OK

    for k in range(N):
        for l in range(N):
            A[k, l] = 0.0
    # ∂²S_u/∂Q^ν∂Q^μ = Am[ν−1, μ−1] M / h (row 0: minus the sum): diagonal blocks
    for mu in range(1, s + 1):
        c0 = (mu - 1) * NQ
        for nu in range(s):
            if nu == 0:
                cM = 0.0
                for k in range(1, s + 1):
                    cM -= Am[k - 1, mu - 1] * inv_h
            else:
                cM = Am[nu - 1, mu - 1] * inv_h
            r0 = nu * NQ
            A[r0, c0] = cM * m1
            A[r0 + 1, c0 + 1] = cM * m1
            A[r0 + 2, c0 + 2] = cM * m2
            A[r0 + 3, c0 + 3] = cM * m2
    for j in range(1, J + 1):
        Gj = G[j]
        row = sn + (j - 1) * NC
        for mu in range(1, s + 1):
            cl = Lc[mu, j]
            if cl != 0.0:
                c0 = (mu - 1) * NQ
                A[row, c0] = cl * Gj[0, 0]
                A[row, c0 + 1] = cl * Gj[0, 1]
                A[row + 1, c0] = cl * Gj[1, 0]
                A[row + 1, c0 + 1] = cl * Gj[1, 1]
                A[row + 1, c0 + 2] = cl * Gj[1, 2]
                A[row + 1, c0 + 3] = cl * Gj[1, 3]
        if j < J:
            # Σ_a η_a ∇²g_a at an interior constraint point
            e2 = X[sn + j * NC + 1]
            ha = X[sn + j * NC] + e2
            for nu in range(s):
                for mu in range(1, s + 1):
                    cc = Lc[nu, j] * Lc[mu, j]
                    if cc != 0.0:
                        r0 = nu * NQ
                        c0 = (mu - 1) * NQ
                        A[r0, c0] -= cc * ha
                        A[r0 + 1, c0 + 1] -= cc * ha
                        A[r0 + 2, c0 + 2] -= cc * e2
                        A[r0 + 3, c0 + 3] -= cc * e2
                        A[r0, c0 + 2] -= cc * -e2
                        A[r0 + 2, c0] -= cc * -e2
                        A[r0 + 1, c0 + 3] -= cc * -e2
                        A[r0 + 3, c0 + 1] -= cc * -e2
    for j in range(J):
        Gj = G[j]
        col = sn + j * NC
        for nu in range(s):
            cl = Lc[nu, j]
            if cl != 0.0:
                r0 = nu * NQ
                A[r0, col] = -cl * Gj[0, 0]
                A[r0, col + 1] = -cl * Gj[1, 0]
                A[r0 + 1, col] = -cl * Gj[0, 1]
                A[r0 + 1, col + 1] = -cl * Gj[1, 1]
                A[r0 + 2, col + 1] = -cl * Gj[1, 2]
                A[r0 + 3, col + 1] = -cl * Gj[1, 3]
    return OK


@hot
def predict(tabs, s, J, h, vk, X, Xp, Xpp, Z, hist, order):
    """The generic predictor (``fastvi.kernels.step.predict``, its extrapolation shared): of
    ``order`` 0 the straight line, 1 the last step's polynomial (``E``), 2 the last two
    steps' (``E2``) where it agrees with the former to ``PREDICT_TRUST``."""
    b, L, Ld, Lc, E, tau = tabs.b, tabs.L, tabs.Ld, tabs.Lc, tabs.E, tabs.tau
    sn = s * NQ
    if order == 0:
        for nu in range(1, s + 1):
            for a in range(NQ):
                X[(nu - 1) * NQ + a] = h * tau[nu] * vk[a]
        for k in range(sn, sn + J * NC):
            X[k] = 0.0
        return
    extrapolate(E, tabs.E2, Xp, Xpp, X, Z, s, NQ, order >= 2 and hist[0] >= 2, h, vk)
    for k in range(sn, sn + J * NC):
        X[k] = Xp[k]


@hot
def newton(prm, tabs, h, qk, pk, ws, piv, tol, max_iter, out):
    """The generic ``newton``: increment-based stopping, divergence exit, same LU."""
    b, L, Ld, Lc, E, tau = tabs.b, tabs.L, tabs.Ld, tabs.Lc, tabs.E, tabs.tau
    X, R, Xp, A, D, G, sm, S, Xpp, Z, hist = ws
    qd = sm[0]
    gj = sm[1]
    s = L.shape[0] - 1
    J = Lc.shape[1] - 1
    sn = s * NQ
    N = sn + J * NC
    qscale = 1.0
    for a in range(NQ):
        qscale = max(qscale, abs(qk[a]))
    dprev = np.inf
    grew = 0
    it = 0
    while it < max_iter:
        it += 1
        out[0] = it
        st = assemble(prm, tabs, h, qk, pk, X, R, A, D, G, qd, gj, True)
        if st != OK:
            return st
        if lu_factor(A, piv[0], N) != 0:
            return SINGULAR
        lu_solve(A, piv[0], R, N)
        dn = 0.0
        for k in range(N):
            X[k] -= R[k]
        for k in range(sn):
            dn = max(dn, abs(R[k]))
        dn /= qscale
        if not np.isfinite(dn):
            return NONFINITE
        if dn <= tol:
            return OK
        if it >= 2:
            theta = dn / dprev
            if theta < 1.0 and theta / (1.0 - theta) * dn <= tol:
                return OK
            if theta >= 0.5 and dn <= 100.0 * tol:
                return OK  # round-off plateau
            grew = grew + 1 if theta > 1.0 else 0
            if grew >= 2:
                break
        dprev = dn
    assemble(prm, tabs, h, qk, pk, X, R, A, D, G, qd, gj, False)
    res = 0.0
    for k in range(N):
        res = max(res, abs(R[k]))
    out[3] = res
    return NEWTON


@hot
def step(prm, tabs, h, qk, pk, vk, q1, p1, v1, ws, piv, tol, max_iter, first, out):
    """Advance (q_k, p_k) by one step into (q1, p1, v1); ``out`` as in the generic ``step``."""
    b, L, Ld, Lc, E, tau = tabs.b, tabs.L, tabs.Ld, tabs.Lc, tabs.E, tabs.tau
    X, R, Xp, A, D, G, sm, S, Xpp, Z, hist = ws
    qd = sm[0]
    gj = sm[1]
    P = sm[2]
    Y0 = sm[3]
    Y1 = sm[4]
    pivm = piv[1]
    s = L.shape[0] - 1
    J = Lc.shape[1] - 1
    sn = s * NQ
    N = sn + J * NC
    m1 = prm[0]
    m2 = prm[1]

    G[0, 0, 0] = qk[0]
    G[0, 0, 1] = qk[1]
    G[0, 1, 0] = -(qk[2] - qk[0])
    G[0, 1, 1] = -(qk[3] - qk[1])
    G[0, 1, 2] = qk[2] - qk[0]
    G[0, 1, 3] = qk[3] - qk[1]
    order = 0 if first else hist[0]
    predict(tabs, s, J, h, vk, X, Xp, Xpp, Z, hist, order)
    st = newton(prm, tabs, h, qk, pk, ws, piv, tol, max_iter, out)
    used = 0.0
    while st != OK and order > 0:
        # the generic kernel's retries from guesses of lower degree, down to the straight
        # line through q_k with velocity v_k
        used += out[0]
        order -= 1
        predict(tabs, s, J, h, vk, X, Xp, Xpp, Z, hist, order)
        st = newton(prm, tabs, h, qk, pk, ws, piv, tol, max_iter, out)
    out[0] += used
    if st != OK:
        return st

    st = assemble(prm, tabs, h, qk, pk, X, R, A, D, G, qd, gj, False)
    if st != OK:
        return st
    res = 0.0
    for k in range(N):
        res = max(res, abs(R[k]))
    out[3] = res
    for a in range(NQ):
        q1[a] = qk[a] + X[(s - 1) * NQ + a]

    # P = D_s − Σ_{0<j<J} ℓ_s(d_j) G_jᵀ η_j
    for a in range(NQ):
        P[a] = D[s, a]
    for j in range(1, J):
        cl = Lc[s, j]
        if cl != 0.0:
            x0 = X[sn + j * NC]
            x1 = X[sn + j * NC + 1]
            P[0] -= cl * (G[j, 0, 0] * x0 + G[j, 1, 0] * x1)
            P[1] -= cl * (G[j, 0, 1] * x0 + G[j, 1, 1] * x1)
            P[2] -= cl * (G[j, 1, 2] * x1)
            P[3] -= cl * (G[j, 1, 3] * x1)

    # RATTLE: p1 = P − G1ᵀη with (G M⁻¹ Gᵀ) η = G M⁻¹ P at q1; M⁻¹ is a division
    G1 = G[J]
    v1[0] = P[0] / m1
    v1[1] = P[1] / m1
    v1[2] = P[2] / m2
    v1[3] = P[3] / m2
    Y0[0] = G1[0, 0] / m1  # rows of (M⁻¹Gᵀ)ᵀ
    Y0[1] = G1[0, 1] / m1
    Y1[0] = G1[1, 0] / m1
    Y1[1] = G1[1, 1] / m1
    Y1[2] = G1[1, 2] / m2
    Y1[3] = G1[1, 3] / m2
    eta = gj
    eta[0] = G1[0, 0] * v1[0] + G1[0, 1] * v1[1]
    eta[1] = G1[1, 0] * v1[0] + G1[1, 1] * v1[1] + G1[1, 2] * v1[2] + G1[1, 3] * v1[3]
    S[0, 0] = G1[0, 0] * Y0[0] + G1[0, 1] * Y0[1]
    S[0, 1] = G1[0, 0] * Y1[0] + G1[0, 1] * Y1[1]
    S[1, 0] = G1[1, 0] * Y0[0] + G1[1, 1] * Y0[1]
    S[1, 1] = G1[1, 0] * Y1[0] + G1[1, 1] * Y1[1] + G1[1, 2] * Y1[2] + G1[1, 3] * Y1[3]
    if lu_factor(S, pivm, NC) != 0:
        return SING_CONS
    lu_solve(S, pivm, eta, NC)
    e0 = eta[0]
    e1 = eta[1]
    p1[0] = P[0] - (G1[0, 0] * e0 + G1[1, 0] * e1)
    p1[1] = P[1] - (G1[0, 1] * e0 + G1[1, 1] * e1)
    p1[2] = P[2] - G1[1, 2] * e1
    p1[3] = P[3] - G1[1, 3] * e1
    v1[0] -= Y0[0] * e0 + Y1[0] * e1
    v1[1] -= Y0[1] * e0 + Y1[1] * e1
    v1[2] -= Y1[2] * e1
    v1[3] -= Y1[3] * e1
    for a in range(NQ):
        if not (np.isfinite(p1[a]) and np.isfinite(v1[a])):
            return NONFINITE
    gmax = max(abs(R[sn + (J - 1) * NC]), abs(R[sn + (J - 1) * NC + 1]))
    out[1] = gmax
    gv0 = abs(G1[0, 0] * v1[0] + G1[0, 1] * v1[1])
    gv1 = abs(G1[1, 0] * v1[0] + G1[1, 1] * v1[1] + G1[1, 2] * v1[2] + G1[1, 3] * v1[3])
    out[2] = max(gv0, gv1)
    for k in range(N):
        Xpp[k] = Xp[k]
        Xp[k] = X[k]
    hist[0] = 1 if first else min(hist[0] + 1, 2)
    return OK


@njit
def run(prm, tabs, h, tol, max_iter, state, ws, piv, n_steps, Qs, Vs, Ps, En, Gr, GVr, It, info):
    """``n_steps`` steps from ``state`` rows (q, p, v), saving every step like ``integrate``.

    Row k + 1 of the outputs holds the state after step k (row 0 is the caller's). Returns
    the status; ``info`` = (steps done, Newton iterations, max final residual).
    """
    q, p, v, q1, p1, v1 = state[0], state[1], state[2], state[3], state[4], state[5]
    sout = np.zeros(4)
    m1 = prm[0]
    m2 = prm[1]
    grav = prm[4]
    for k in range(n_steps):
        st = step(prm, tabs, h, q, p, v, q1, p1, v1, ws, piv, tol, max_iter, k == 0, sout)
        info[1] += sout[0]
        if st != OK:
            return st
        info[2] = max(info[2], sout[3])
        for a in range(NQ):
            q[a] = q1[a]
            p[a] = p1[a]
            v[a] = v1[a]
        info[0] = k + 1
        j = k + 1
        for a in range(NQ):
            Qs[j, a] = q[a]
            Vs[j, a] = v[a]
            Ps[j, a] = p[a]
        e = grav * (m1 * q[1] + m2 * q[3])
        for a in range(NQ):
            e += 0.5 * v[a] * p[a]
        En[j] = e
        Gr[j] = sout[1]
        GVr[j] = sout[2]
        It[j] = sout[0]
    return OK


class YardstickError(RuntimeError):
    """A yardstick step failed (the generic kernel's statuses, same meaning)."""

    def __init__(self, status: Status, step: int, iterations: int):
        self.status, self.step, self.iterations = status, step, iterations
        super().__init__(f"yardstick failed: {status.name} at step {step} "
                         f"({iterations} Newton iterations in all)")


def integrate_double_pendulum(q0, v0, *, h, n_steps, tabs, params=(1.0, 1.0, 1.0, 1.0, 9.81),
                              tol=1e-14, max_iter=30):
    """Python driver of the yardstick (no validation: the caller passes a consistent state).

    Parameters
    ----------
    q0, v0 : array_like (4,)
        Consistent initial state ``g(q0) = 0``, ``G(q0) v0 = 0``; ``p0 = M v0``.
    h : float
    n_steps : int
    tabs : tuple of ndarray
        ``fastvi.method(name).kernel_tables`` of any ``PsL-Qr*`` method.
    params : (m1, m2, l1, l2, g)
    tol, max_iter : as in ``fastvi.integrate``.

    Returns
    -------
    dict with ``q``, ``p``, ``v`` (final state), ``energy`` (n_steps + 1,), the series ``qs``,
    ``vs``, ``ps``, ``constraint_residual``, ``velocity_residual``, ``newton_iterations``,
    ``steps``, ``iterations`` (Newton, total), ``max_residual``, ``wall_time``.

    Raises
    ------
    YardstickError
        A step failed; carries ``status`` (:class:`fastvi.Status`), ``step`` (its index) and
        ``iterations`` (Newton iterations spent, the failed step's included).
    """
    prm = np.ascontiguousarray(params, dtype=np.float64)
    L, Lc = tabs.L, tabs.Lc
    s = L.shape[0] - 1
    J = Lc.shape[1] - 1
    N = s * NQ + J * NC
    q0 = np.asarray(q0, dtype=np.float64)
    v0 = np.asarray(v0, dtype=np.float64)
    mass = np.array([prm[0], prm[0], prm[1], prm[1]])
    state = np.zeros((6, NQ))
    state[0], state[1], state[2] = q0, mass * v0, v0
    ws = (np.zeros(N), np.zeros(N), np.zeros(N), np.zeros((N, N)), np.zeros((s + 1, NQ)),
          np.zeros((J + 1, NC, NQ)), np.zeros((5, NQ)), np.zeros((NC, NC)), np.zeros(N),
          np.zeros((s, NQ)), np.zeros(1, dtype=np.int64))
    piv = np.zeros((2, N), dtype=np.int64)
    K = n_steps + 1
    Qs, Vs, Ps = np.zeros((K, NQ)), np.zeros((K, NQ)), np.zeros((K, NQ))
    En, Gr, GVr, It = np.zeros(K), np.zeros(K), np.zeros(K), np.zeros(K)
    Qs[0], Vs[0], Ps[0] = q0, v0, state[1]
    En[0] = prm[4] * (prm[0] * q0[1] + prm[1] * q0[3]) + 0.5 * float(v0 @ state[1])
    info = np.zeros(3)
    t0 = time.perf_counter()
    st = run(prm, tabs, float(h), float(tol), int(max_iter), state, ws, piv, int(n_steps),
             Qs, Vs, Ps, En, Gr, GVr, It, info)
    wall = time.perf_counter() - t0
    if st != OK:
        raise YardstickError(Status(st), int(info[0]), int(info[1]))
    return dict(q=state[0].copy(), p=state[1].copy(), v=state[2].copy(), energy=En, qs=Qs, vs=Vs,
                ps=Ps, constraint_residual=Gr, velocity_residual=GVr, newton_iterations=It,
                steps=int(info[0]), iterations=int(info[1]), max_residual=float(info[2]),
                wall_time=wall)
