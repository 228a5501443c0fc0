r"""One step of the constrained Galerkin variational integrator (``docs/method.md``).

Unknowns ``X = (ΔQ^1 … ΔQ^s, η_0 … η_{J−1})`` with ``ΔQ^ν = Q^ν − q_k`` (increments keep
the step well scaled and exactly variational, given consistent tables) and the constraint
impulses ``η_j``. Residual rows ``(E_0 … E_{s−1}, C_1 … C_J)``:

    E_ν = δ_{ν0} p_k + ∂S_u/∂Q^ν − Σ_{j<J} ℓ_ν(d_j) G_jᵀ η_j
    C_j = g(q(d_j))

with ``∂S_u/∂Q^ν = h Σ_i b_i [ℓ_ν(c_i) ∂L/∂q + (1/h) ℓ'_ν(c_i) M v](q_i, v_i)``. After Newton,

    P = ∂S_u/∂Q^s − Σ_{j<J} ℓ_s(d_j) G_jᵀ η_j,   p_{k+1} = P − G(q_{k+1})ᵀ η_J,
    (G M⁻¹ Gᵀ) η_J = G M⁻¹ P   at q_{k+1}                      (RATTLE projection)

Workspace, model and method are plain arrays and cfuncs; nothing here allocates.
"""

import numpy as np

from .._numba import njit, ptr
from ..status import Status
from .linalg import lu_factor, lu_solve

# indices of SLOTS in fastvi.model
_MASS, _KGRAD, _POT, _PGRAD, _CON, _CJAC, _PHESS, _CHESS, _KHESS, _MJAC = range(10)
# indices of the flags vector (fastvi.model._compile)
_F_N, _F_M, _F_MASSFN, _F_EX_PHESS, _F_EX_CHESS, _F_EX_KHESS, _F_EX_MJAC, _F_DIAG = range(8)
_FD_REL = 6.0554544523933395e-06  # cbrt(machine epsilon): central differences' best step

# status as plain ints inside kernels
_OK = int(Status.SUCCESS)
_NEWTON = int(Status.NEWTON_NOT_CONVERGED)
_SINGULAR = int(Status.SINGULAR_JACOBIAN)
_NONFINITE = int(Status.NONFINITE)
_SING_MASS = int(Status.SINGULAR_MASS)
_SING_CONS = int(Status.SINGULAR_CONSTRAINTS)


@njit
def make_workspace(n, m, s, r, J):
    """Scratch arrays for one trajectory (allocated once, outside the time loop)."""
    N = s * n + J * m
    mm = max(m, 1)
    return (
        np.zeros(N),  # 0 X: unknowns
        np.zeros(N),  # 1 R: residual, then Newton increment
        np.zeros((N, N)),  # 2 A: Newton matrix, factored in place
        np.zeros(N, dtype=np.int64),  # 3 piv
        np.zeros((s + 1, n)),  # 4 D: ∂S_u/∂Q^ν
        np.zeros((J + 1, mm, n)),  # 5 G at the constraint points
        np.zeros((6, n)),  # 6 vectors: q_i, v_i, F, Mv, fd+, fd-
        np.zeros((5, n, n)),  # 7 matrices: M_i, ∂F/∂q, ∂(Mv)/∂q, constraint Hessian, fd
        np.zeros((3, mm, n)),  # 8 Y = M⁻¹Gᵀ (transposed), fd G+, fd G-
        np.zeros((2, mm)),  # 9 g, η_J
        np.zeros((mm, mm)),  # 10 S = G M⁻¹ Gᵀ
        np.zeros(mm, dtype=np.int64),  # 11 pivm
        np.zeros(n, dtype=np.int64),  # 12 pivn
        np.zeros(N),  # 13 X of the previous step (predictor)
        np.zeros(n),  # 14 P, then z = M⁻¹P
    )


# ----------------------------------------------------------------------------- derivatives
@njit
def _fd_vec_jacobian(fn, slot_kind, q, v, prm, out, qa, fa, fb, n):
    """out[:, b] = ∂f/∂q_b by central differences of a vector callback f(q, v)."""
    for b in range(n):
        for a in range(n):
            qa[a] = q[a]
        dq = _FD_REL * max(1.0, abs(q[b]))
        qa[b] = q[b] + dq
        fn(ptr(qa), ptr(v), ptr(prm), ptr(fa))
        qa[b] = q[b] - dq
        fn(ptr(qa), ptr(v), ptr(prm), ptr(fb))
        inv = 0.5 / dq
        for a in range(n):
            out[a, b] = (fa[a] - fb[a]) * inv
    if slot_kind == 1:  # a Hessian: symmetrise
        for a in range(n):
            for b in range(a + 1, n):
                t = 0.5 * (out[a, b] + out[b, a])
                out[a, b] = t
                out[b, a] = t


@njit
def _fd_momentum_jacobian(fmass, q, v, prm, out, qa, Ma, n):
    """out[a, b] = ∂(M(q) v)_a / ∂q_b by central differences of the mass callback."""
    for b in range(n):
        for a in range(n):
            qa[a] = q[a]
        dq = _FD_REL * max(1.0, abs(q[b]))
        qa[b] = q[b] + dq
        fmass(ptr(qa), ptr(qa), ptr(prm), ptr(Ma))
        for a in range(n):
            acc = 0.0
            for c in range(n):
                acc += Ma[a, c] * v[c]
            out[a, b] = acc
        qa[b] = q[b] - dq
        fmass(ptr(qa), ptr(qa), ptr(prm), ptr(Ma))
        inv = 0.5 / dq
        for a in range(n):
            acc = 0.0
            for c in range(n):
                acc += Ma[a, c] * v[c]
            out[a, b] = (out[a, b] - acc) * inv


@njit
def _fd_constraint_hessian(fjac, q, eta, prm, out, qa, Gp, Gm, n, m):
    """out = Σ_a η_a ∇²g_a = ∂(Gᵀη)/∂q by central differences of the Jacobian callback."""
    for b in range(n):
        for a in range(n):
            qa[a] = q[a]
        dq = _FD_REL * max(1.0, abs(q[b]))
        qa[b] = q[b] + dq
        fjac(ptr(qa), ptr(qa), ptr(prm), ptr(Gp))
        qa[b] = q[b] - dq
        fjac(ptr(qa), ptr(qa), ptr(prm), ptr(Gm))
        inv = 0.5 / dq
        for a in range(n):
            acc = 0.0
            for c in range(m):
                acc += (Gp[c, a] - Gm[c, a]) * eta[c]
            out[a, b] = acc * inv
    for a in range(n):
        for b in range(a + 1, n):
            t = 0.5 * (out[a, b] + out[b, a])
            out[a, b] = t
            out[b, a] = t


# ----------------------------------------------------------------------------- assembly
@njit
def assemble(fns, flags, Mc, prm, tabs, h, qk, pk, ws, jac):
    """Residual (and, if ``jac``, the Newton matrix) at the unknowns ``ws[0]``.

    Returns 0, or ``NONFINITE`` when a callback produced NaN/inf.
    """
    b, L, Ld, Lc, E, tau = tabs
    X, R, A = ws[0], ws[1], ws[2]
    D, G = ws[4], ws[5]
    vecs, mats, gfd, gvec = ws[6], ws[7], ws[8], ws[9]
    qi, vi, F, Pm, fa, fb = vecs[0], vecs[1], vecs[2], vecs[3], vecs[4], vecs[5]
    Aq, Cq, Hc, Ma = mats[1], mats[2], mats[3], mats[4]
    gj = gvec[0]
    n = flags[_F_N]
    m = flags[_F_M]
    has_mass = flags[_F_MASSFN] != 0
    diag = flags[_F_DIAG] != 0
    s = L.shape[0] - 1
    r = L.shape[1]
    J = Lc.shape[1] - 1
    sn = s * n
    N = sn + J * m
    inv_h = 1.0 / h

    for k in range(N):
        R[k] = 0.0
    if jac:
        for k in range(N):
            for l in range(N):
                A[k, l] = 0.0
    for nu in range(s + 1):
        for a in range(n):
            D[nu, a] = 0.0

    Mi = Mc if not has_mass else mats[0]
    for i in range(r):
        for a in range(n):
            qa = qk[a]
            va = 0.0
            for nu in range(1, s + 1):
                x = X[(nu - 1) * n + a]
                qa += L[nu, i] * x
                va += Ld[nu, i] * x
            qi[a] = qa
            vi[a] = va * inv_h
        fns[_PGRAD](ptr(qi), ptr(qi), ptr(prm), ptr(fa))
        if has_mass:
            fns[_KGRAD](ptr(qi), ptr(vi), ptr(prm), ptr(F))
            fns[_MASS](ptr(qi), ptr(qi), ptr(prm), ptr(Mi))
            for a in range(n):
                F[a] -= fa[a]
        else:
            for a in range(n):
                F[a] = -fa[a]
        if diag:
            for a in range(n):
                Pm[a] = Mi[a, a] * vi[a]
        else:
            for a in range(n):
                acc = 0.0
                for c in range(n):
                    acc += Mi[a, c] * vi[c]
                Pm[a] = acc
        w = h * b[i]
        for nu in range(s + 1):
            cl = w * L[nu, i]
            cd = b[i] * Ld[nu, i]
            for a in range(n):
                D[nu, a] += cl * F[a] + cd * Pm[a]
        if not jac:
            continue
        # ∂F/∂q = T_qq − V_qq ; ∂(Mv)/∂q
        if flags[_F_EX_PHESS] != 0:
            fns[_PHESS](ptr(qi), ptr(qi), ptr(prm), ptr(Aq))
        else:
            _fd_vec_jacobian(fns[_PGRAD], 1, qi, qi, prm, Aq, fa, F, Pm, n)  # F, Pm: spent scratch
        for a in range(n):
            for c in range(n):
                Aq[a, c] = -Aq[a, c]
        if has_mass:
            if flags[_F_EX_KHESS] != 0:
                fns[_KHESS](ptr(qi), ptr(vi), ptr(prm), ptr(Hc))
            else:
                _fd_vec_jacobian(fns[_KGRAD], 1, qi, vi, prm, Hc, fa, F, Pm, n)
            for a in range(n):
                for c in range(n):
                    Aq[a, c] += Hc[a, c]
            if flags[_F_EX_MJAC] != 0:
                fns[_MJAC](ptr(qi), ptr(vi), ptr(prm), ptr(Cq))
            else:
                _fd_momentum_jacobian(fns[_MASS], qi, vi, prm, Cq, fa, Ma, n)
        for nu in range(s):
            for mu in range(1, s + 1):
                cA = w * L[nu, i] * L[mu, i]
                cM = b[i] * Ld[nu, i] * Ld[mu, i] * inv_h
                r0 = nu * n
                c0 = (mu - 1) * n
                for a in range(n):
                    for c in range(n):
                        A[r0 + a, c0 + c] += cA * Aq[a, c] + cM * Mi[a, c]
                if has_mass:
                    # ∂/∂Q^μ of ℓ_ν ∂T/∂q and of ℓ'_ν M v: the mixed terms, B = Cqᵀ
                    cB = b[i] * L[nu, i] * Ld[mu, i]
                    cC = b[i] * Ld[nu, i] * L[mu, i]
                    for a in range(n):
                        for c in range(n):
                            A[r0 + a, c0 + c] += cB * Cq[c, a] + cC * Cq[a, c]

    for a in range(n):
        R[a] = pk[a]
    for nu in range(s):
        for a in range(n):
            R[nu * n + a] += D[nu, a]

    if m > 0:
        qd = vecs[0]
        for j in range(1, J + 1):
            for a in range(n):
                qa = qk[a]
                for nu in range(1, s + 1):
                    qa += Lc[nu, j] * X[(nu - 1) * n + a]
                qd[a] = qa
            fns[_CON](ptr(qd), ptr(qd), ptr(prm), ptr(gj))
            Gj = G[j]
            fns[_CJAC](ptr(qd), ptr(qd), ptr(prm), ptr(Gj))
            row = sn + (j - 1) * m
            for a in range(m):
                R[row + a] = gj[a]
            if jac:
                for mu in range(1, s + 1):
                    cl = Lc[mu, j]
                    if cl != 0.0:
                        c0 = (mu - 1) * n
                        for a in range(m):
                            for c in range(n):
                                A[row + a, c0 + c] = cl * Gj[a, c]
                if j < J:
                    eta = X[sn + j * m : sn + (j + 1) * m]
                    if flags[_F_EX_CHESS] != 0:
                        fns[_CHESS](ptr(qd), ptr(eta), ptr(prm), ptr(Hc))
                    else:
                        _fd_constraint_hessian(fns[_CJAC], qd, eta, prm, Hc, fa, gfd[1], gfd[2], n, m)
                    for nu in range(s):
                        for mu in range(1, s + 1):
                            cc = Lc[nu, j] * Lc[mu, j]
                            if cc != 0.0:
                                r0 = nu * n
                                c0 = (mu - 1) * n
                                for a in range(n):
                                    for c in range(n):
                                        A[r0 + a, c0 + c] -= cc * Hc[a, c]
        for j in range(J):
            Gj = G[j]
            col = sn + j * m
            for nu in range(s):
                cl = Lc[nu, j]
                if cl == 0.0:
                    continue
                r0 = nu * n
                for a in range(n):
                    acc = 0.0
                    for c in range(m):
                        acc += Gj[c, a] * X[col + c]
                    R[r0 + a] -= cl * acc
                if jac:
                    for a in range(n):
                        for c in range(m):
                            A[r0 + a, col + c] = -cl * Gj[c, a]

    for k in range(N):
        if not np.isfinite(R[k]):
            return _NONFINITE
    return _OK


# ----------------------------------------------------------------------------- one step
@njit
def predict(tabs, n, m, s, J, h, vk, ws, first):
    """Initial guess: the previous step's polynomial extrapolated onto this step."""
    b, L, Ld, Lc, E, tau = tabs
    X = ws[0]
    Xp = ws[13]
    if first:
        # straight line with the initial velocity; impulses start at zero
        for nu in range(1, s + 1):
            for a in range(n):
                X[(nu - 1) * n + a] = h * tau[nu] * vk[a]
        for k in range(s * n, s * n + J * m):
            X[k] = 0.0
        return
    sn = s * n
    for nu in range(1, s + 1):
        for a in range(n):
            last = Xp[(s - 1) * n + a]
            acc = -last * E[0, nu]  # μ = 0: ΔQ^0 = 0
            for mu in range(1, s + 1):
                acc += (Xp[(mu - 1) * n + a] - last) * E[mu, nu]
            X[(nu - 1) * n + a] = acc
    for k in range(sn, sn + J * m):
        X[k] = Xp[k]


@njit
def newton(fns, flags, Mc, prm, tabs, h, qk, pk, ws, tol, max_iter, out):
    """Newton's method on the step equations from the unknowns in ``ws[0]``.

    Stops on the increment of the control points, scaled by ``max(1, |q_k|)``: converged
    when it is below ``tol``, when the contraction estimate ``θ/(1−θ)·|δ|`` predicts the
    remaining error below ``tol``, or at a round-off plateau (``θ ≥ ½`` with ``|δ| ≤ 100
    tol``). A residual test on the momentum rows would leave an error ~tol/h per step.
    Gives up early when the increments grow twice in a row (divergence).
    """
    b, L, Ld, Lc, E, tau = tabs
    X, R, A, piv = ws[0], ws[1], ws[2], ws[3]
    n = flags[0]
    m = flags[1]
    s = L.shape[0] - 1
    J = Lc.shape[1] - 1
    sn = s * n
    N = sn + J * m
    qscale = 1.0
    for a in range(n):
        qscale = max(qscale, abs(qk[a]))
    dprev = np.inf
    grew = 0
    it = 0
    while it < max_iter:
        it += 1
        out[0] = it
        st = assemble(fns, flags, Mc, prm, tabs, h, qk, pk, ws, True)
        if st != _OK:
            return st
        if lu_factor(A, piv, N) != 0:
            return _SINGULAR
        lu_solve(A, piv, R, N)
        dn = 0.0
        for k in range(N):
            X[k] -= R[k]
        for k in range(sn):
            dn = max(dn, abs(R[k]))
        dn /= qscale
        if not np.isfinite(dn):
            return _NONFINITE
        if dn <= tol:
            return _OK
        if it >= 2:
            theta = dn / dprev
            if theta < 1.0 and theta / (1.0 - theta) * dn <= tol:
                return _OK
            if theta >= 0.5 and dn <= 100.0 * tol:
                return _OK  # round-off plateau
            grew = grew + 1 if theta > 1.0 else 0
            if grew >= 2:
                break
        dprev = dn
    assemble(fns, flags, Mc, prm, tabs, h, qk, pk, ws, False)
    res = 0.0
    for k in range(N):
        res = max(res, abs(R[k]))
    out[3] = res
    return _NEWTON


@njit
def step(fns, flags, Mc, prm, tabs, h, qk, pk, vk, q1, p1, v1, ws, tol, max_iter, first, out):
    """Advance (q_k, p_k) by one step into (q1, p1, v1).

    ``out`` (float64, ≥ 4) receives: Newton iterations, max|g(q1)|, max|G(q1) v1|, and the
    final max-norm of the residual. Returns a status code (0 on success).
    """
    b, L, Ld, Lc, E, tau = tabs
    X, R, A, piv = ws[0], ws[1], ws[2], ws[3]
    D, G = ws[4], ws[5]
    n = flags[0]
    m = flags[1]
    s = L.shape[0] - 1
    J = Lc.shape[1] - 1
    sn = s * n
    N = sn + J * m

    if m > 0:
        G0 = G[0]
        if first:
            fns[_CJAC](ptr(qk), ptr(qk), ptr(prm), ptr(G0))
        else:
            # the previous step ended with G at q(d_J) = q_k, bit for bit: reuse it
            for a in range(m):
                for c in range(n):
                    G0[a, c] = G[J, a, c]
    predict(tabs, n, m, s, J, h, vk, ws, first)
    st = newton(fns, flags, Mc, prm, tabs, h, qk, pk, ws, tol, max_iter, out)
    if st != _OK and not first:
        # The extrapolated polynomial can be far off (stiff oscillations with ωh > 1, a
        # sudden turn): start again from the straight line through q_k with velocity v_k.
        used = out[0]
        predict(tabs, n, m, s, J, h, vk, ws, True)
        st = newton(fns, flags, Mc, prm, tabs, h, qk, pk, ws, tol, max_iter, out)
        out[0] += used
    if st != _OK:
        return st

    # final residual at the converged unknowns: exact D_s for the momentum, and g(q1)
    st = assemble(fns, flags, Mc, prm, tabs, h, qk, pk, ws, False)
    if st != _OK:
        return st
    res = 0.0
    for k in range(N):
        res = max(res, abs(R[k]))
    out[3] = res
    for a in range(n):
        q1[a] = qk[a] + X[(s - 1) * n + a]

    # P = D_s − Σ_{j<J} ℓ_s(d_j) G_jᵀ η_j
    P = ws[14]
    for a in range(n):
        P[a] = D[s, a]
    for j in range(1, J):
        cl = Lc[s, j]
        if cl != 0.0:
            for a in range(n):
                acc = 0.0
                for c in range(m):
                    acc += G[j, c, a] * X[sn + j * m + c]
                P[a] -= cl * acc
    st = end_momentum(fns, flags, Mc, prm, q1, P, p1, v1, G[J], ws)
    if st != _OK:
        return st
    gmax = 0.0
    for a in range(m):
        gmax = max(gmax, abs(R[sn + (J - 1) * m + a]))
    out[1] = gmax
    out[2] = velocity_residual(G[J], v1, n, m)
    # keep this step's unknowns for the next predictor
    Xp = ws[13]
    for k in range(N):
        Xp[k] = X[k]
    return _OK


@njit
def velocity_residual(G1, v1, n, m):
    """max_a |(G v)_a|."""
    gv = 0.0
    for a in range(m):
        acc = 0.0
        for c in range(n):
            acc += G1[a, c] * v1[c]
        gv = max(gv, abs(acc))
    return gv


@njit
def end_momentum(fns, flags, Mc, prm, q1, P, p1, v1, G1, ws):
    """p1 = P − G1ᵀ η with (G M⁻¹ Gᵀ) η = G M⁻¹ P, and v1 = M⁻¹ p1 (hidden constraint)."""
    n = flags[0]
    m = flags[1]
    Mlu = ws[7][0]
    pivn = ws[12]
    Y = ws[8][0]
    gvec = ws[9]
    S = ws[10]
    pivm = ws[11]
    diag = flags[_F_DIAG] != 0
    if diag:
        for a in range(n):
            v1[a] = P[a] / Mc[a, a]  # z = M⁻¹ P
    else:
        if flags[_F_MASSFN] != 0:
            fns[_MASS](ptr(q1), ptr(q1), ptr(prm), ptr(Mlu))
        else:
            for a in range(n):
                for c in range(n):
                    Mlu[a, c] = Mc[a, c]
        if lu_factor(Mlu, pivn, n) != 0:
            return _SING_MASS
        for a in range(n):
            v1[a] = P[a]
        lu_solve(Mlu, pivn, v1, n)  # z = M⁻¹ P
    if m > 0:
        for c in range(m):
            Yc = Y[c]
            for a in range(n):
                Yc[a] = G1[c, a]
            if diag:
                for a in range(n):
                    Yc[a] /= Mc[a, a]
            else:
                lu_solve(Mlu, pivn, Yc, n)  # row c of (M⁻¹ Gᵀ)ᵀ
        eta = gvec[1]
        for c in range(m):
            acc = 0.0
            for a in range(n):
                acc += G1[c, a] * v1[a]
            eta[c] = acc
            for d in range(m):
                acc = 0.0
                for a in range(n):
                    acc += G1[c, a] * Y[d, a]
                S[c, d] = acc
        if lu_factor(S, pivm, m) != 0:
            return _SING_CONS
        lu_solve(S, pivm, eta, m)
        for a in range(n):
            acc = 0.0
            acc2 = 0.0
            for c in range(m):
                acc += G1[c, a] * eta[c]
                acc2 += Y[c, a] * eta[c]
            p1[a] = P[a] - acc
            v1[a] -= acc2
    else:
        for a in range(n):
            p1[a] = P[a]
    for a in range(n):
        if not (np.isfinite(p1[a]) and np.isfinite(v1[a])):
            return _NONFINITE
    return _OK
