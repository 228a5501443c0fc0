r"""Structured linear solves of a step (issue 12): banded LU and sparse products with G.

Large mechanisms give sparse Newton matrices: ordered by body, a chain's is banded. Each
linear system of a step — the full Newton matrix, the Schur complement of the mechanics
iteration on the impulses and the end projection ``G M⁻¹ Gᵀ`` — is solved either by the
dense LU of :mod:`.linalg` or, when :func:`fastvi.structure.plan` chose it for the model and
method, by a banded LU with partial pivoting after a fill-reducing (reverse Cuthill–McKee)
ordering computed once in NumPy, or — the Schur complement and the projection, for
patterns a band does not fit — by the sparse LU of :mod:`.sparse_lu`. The choice and the
data sit in two workspace arrays, ``ws.si`` (int64, header ``SI_*`` of :mod:`.layout`) and
``ws.sb`` (float64). The Schur complement and the projection are assembled over the pattern
of ``G Gᵀ`` straight into their factor storage, at destinations computed at planning time
(``SI_SC_DST``, ``SI_S_DST``), so banded and sparse storage share one assembly loop.

Band storage is LAPACK's (``dgbtrf``): with ``kv = kl + ku`` and ``ld = 2 kl + ku + 1``,
entry ``(i, j)`` of the permuted matrix sits at ``ab[kv + i − j + ld j]`` (column-major,
one flat array); the top ``kl`` rows take the fill of row interchanges. Hand-written rather
than LAPACK through ``cython_lapack``: the bands here are narrow (``kl + ku`` ≈ 10–20) and
a plain numba loop needs no function pointer baked into a cached kernel.

A Newton matrix too large to hold densely (the full Newton's of a long chain, or the
derivatives' extended step's) is assembled straight into that band storage: each write
goes through a map stored in ``ws.si`` (:func:`assembly_offset`, built in NumPy by
:func:`.layout.assembly_into_band`), and the factorisation then works in place.
"""

import numpy as np
from numba.core import types
from numba.extending import overload

from .._numba import hot, hot_inline, only_if, own
from .layout import (NONFINITE, OK, S_GV, SI_A_BAND, SI_A_KL, SI_A_KU, SI_A_PERM, SI_GCOL, SI_GPTR,
                     SI_RHS, SI_S, SI_S_BAND, SI_S_DST, SI_S_IPERM, SI_S_KL, SI_S_KU, SI_S_LEN,
                     SI_S_LU, SI_S_PERM, SI_SC, SI_SC_BAND, SI_SC_DST, SI_SC_KL, SI_SC_KU,
                     SI_SC_LEN, SI_SC_LU, SI_SC_PERM, SI_SCOL, SI_SPTR, SI_XMAP,
                     SINGULAR_CONSTRAINTS, SOLVE_BANDED, XM_KL, XM_KU, XM_N, XM_SIZE,
                     XMAP_HEADER)
from .sparse_lu import sparse_factor, sparse_solve

__all__ = ["band_factor", "band_solve", "band_solve_transposed", "band_pack", "newton_banded", "schur_structured",
           "schur_solve_structured", "mech_impulses_structured", "g_times", "gt_times", "band_ld",
           "mech_rows_sparse", "project_structured", "gmg_factor", "gmg_solve", "assembly_map",
           "assembly_offset", "add_entry", "put_entry", "clear_band"]


@hot_inline
def band_ld(kl, ku):
    """Leading dimension of the band storage: ``2 kl + ku + 1``."""
    return 2 * kl + ku + 1


@hot
def band_factor(ab, piv, N, kl, ku):
    """Factor the band matrix in ``ab`` in place as P A = L U (LAPACK ``dgbtf2``).

    Returns 0, or ``k + 1`` if the pivot of column ``k`` is zero or not finite.
    """
    kv = kl + ku
    ld = 2 * kl + ku + 1
    ju = 0
    for j in range(N):
        km = min(kl, N - 1 - j)
        cj = ld * j
        jp = 0
        big = abs(ab[cj + kv])
        for i in range(1, km + 1):
            a = abs(ab[cj + kv + i])
            if a > big:
                big = a
                jp = i
        piv[j] = j + jp
        if not (big > 0.0) or not np.isfinite(big):
            return j + 1
        ju = max(ju, min(j + ku + jp, N - 1))
        if jp != 0:
            for c in range(j, ju + 1):
                o = ld * c + kv + j - c
                t = ab[o]
                ab[o] = ab[o + jp]
                ab[o + jp] = t
        if km > 0:
            inv = 1.0 / ab[cj + kv]
            for i in range(1, km + 1):
                ab[cj + kv + i] *= inv
            for c in range(j + 1, ju + 1):
                o = ld * c + kv + j - c
                u = ab[o]
                if u != 0.0:
                    for i in range(1, km + 1):
                        ab[o + i] -= ab[cj + kv + i] * u
    return 0


@hot
def band_solve(ab, piv, b, N, kl, ku):
    """Solve with the factors of :func:`band_factor`; ``b`` (length ≥ N) is overwritten."""
    kv = kl + ku
    ld = 2 * kl + ku + 1
    if kl > 0:
        for j in range(N - 1):
            lm = min(kl, N - 1 - j)
            p = piv[j]
            if p != j:
                t = b[p]
                b[p] = b[j]
                b[j] = t
            bj = b[j]
            if bj != 0.0:
                cj = ld * j + kv
                for i in range(1, lm + 1):
                    b[j + i] -= ab[cj + i] * bj
    for j in range(N - 1, -1, -1):
        cj = ld * j + kv
        b[j] /= ab[cj]
        bj = b[j]
        if bj != 0.0:
            for i in range(max(0, j - kv), j):
                b[i] -= ab[cj + i - j] * bj


@hot
def band_solve_transposed(ab, piv, b, N, kl, ku):
    """Solve ``Aᵀ x = b`` with the factors of :func:`band_factor` (LAPACK ``dgbtrs``,
    ``trans = 'T'``: ``Uᵀ``, then ``Lᵀ`` with the row interchanges in reverse); ``b``
    (length ≥ N) is overwritten."""
    kv = kl + ku
    ld = 2 * kl + ku + 1
    for j in range(N):
        cj = ld * j + kv
        acc = b[j]
        for i in range(max(0, j - kv), j):
            acc -= ab[cj + i - j] * b[i]
        b[j] = acc / ab[cj]
    if kl > 0:
        for j in range(N - 2, -1, -1):
            lm = min(kl, N - 1 - j)
            cj = ld * j + kv
            acc = b[j]
            for i in range(1, lm + 1):
                acc -= ab[cj + i] * b[j + i]
            b[j] = acc
            p = piv[j]
            if p != j:
                t = b[p]
                b[p] = b[j]
                b[j] = t


@hot
def band_pack(A, perm, ab, N, kl, ku):
    """``ab`` ← the band of ``A[perm][:, perm]`` (entries outside the band are dropped)."""
    kv = kl + ku
    ld = 2 * kl + ku + 1
    for k in range(ld * N):
        ab[k] = 0.0
    for j in range(N):
        pj = perm[j]
        for i in range(max(0, j - ku), min(N, j + kl + 1)):
            ab[ld * j + kv + i - j] = A[perm[i], pj]


@hot_inline
def _over_span(si, o, x, spare):
    """The place of entry ``x`` of a row (column) stored over its span, ``(base, lo, hi)``
    at ``si[o]``; ``spare`` outside it."""
    if x < si[o + 1] or x >= si[o + 2]:
        return spare
    return si[o] + x - si[o + 1]


@hot
def assembly_offset(si, xm, r, c):
    """Where entry ``(r, c)`` of a Newton matrix sits in the storage ``A[0]`` of an assembly
    by the map ``xm`` (:func:`assembly_map`): in the band storage of the step's matrix
    ``K`` in its banded ordering (as :func:`band_pack` would leave it); for the
    derivatives' extended step, in the extended rows' own columns ``T_q`` (each row over
    its span), or in the extended step's own rows ``P_X`` (stored by columns of ``K``, each
    over its span). An entry outside these (zero: the band and the spans were chosen to
    hold the pattern) goes to the last cell, which no one reads. Called, not inlined: typed
    once, not at every write of the assembly."""
    at, N, kl, ku, tq, px, spare, pos = xm[1], xm[2], xm[3], xm[4], xm[5], xm[6], xm[7], xm[8]
    i = si[at + r]
    j = si[at + c]
    if j >= N:  # T_q: (base, lo, hi) of each row
        return _over_span(si, tq + 3 * i, j - N, spare)
    if i >= N:  # P_X: (base, lo, hi) of each column
        return _over_span(si, px + 3 * j, i - N, spare)
    pj = si[pos + j]
    d = si[pos + i] - pj
    if d > kl or d < -ku:
        return spare
    return (2 * kl + ku + 1) * pj + kl + ku + d


# The writes of the assembly: ``xm`` is None for a small model's workspace (its type says
# it has no map), and the overloads below then compile to the plain store alone; a
# run-time branch would leave the map's code to be typed at every write all the same.
def add_entry(A, si, xm, r, c, x):
    """``A[r, c] += x``; by the map ``xm`` where there is one (:func:`assembly_offset`)."""


def put_entry(A, si, xm, r, c, x):
    """``A[r, c] = x``, as :func:`add_entry`."""


def clear_band(A, xm):
    """The band of an assembly by the map ``xm`` ← 0 (nothing without one)."""


def _add_plain(A, si, xm, r, c, x):
    A[r, c] += x


def _add_mapped(A, si, xm, r, c, x):
    if xm[0] == 0:
        A[r, c] += x
    else:
        A[0, assembly_offset(si, xm, r, c)] += x


def _put_plain(A, si, xm, r, c, x):
    A[r, c] = x


def _put_mapped(A, si, xm, r, c, x):
    if xm[0] == 0:
        A[r, c] = x
    else:
        A[0, assembly_offset(si, xm, r, c)] = x


def _zero_band_plain(A, xm):
    pass


def _zero_band_mapped(A, xm):
    if xm[0] != 0:  # the whole band, which the last factorisation filled
        for k in range((2 * xm[3] + xm[4] + 1) * xm[2]):
            A[0, k] = 0.0


@overload(add_entry, jit_options=dict(_nrt=False))
def _add_typed(A, si, xm, r, c, x):
    return _add_plain if isinstance(xm, types.NoneType) else _add_mapped


@overload(put_entry, jit_options=dict(_nrt=False))
def _put_typed(A, si, xm, r, c, x):
    return _put_plain if isinstance(xm, types.NoneType) else _put_mapped


@overload(clear_band, jit_options=dict(_nrt=False))
def _zero_band_typed(A, xm):
    return _zero_band_plain if isinstance(xm, types.NoneType) else _zero_band_mapped


def mapped(xm):
    """Whether ``xm`` (:func:`assembly_map`) is a map: false by type for None."""


@overload(mapped, jit_options=dict(_nrt=False))
def _mapped_typed(xm):
    if isinstance(xm, types.NoneType):
        return lambda xm: False
    return lambda xm: xm[0] != 0


@hot
def _assembly_map(ws_):
    """The map by which a structured workspace's Newton matrix is assembled into band
    storage (:func:`assembly_offset`), read once from ``si[SI_XMAP]``: ``(offset, at, N, kl,
    ku, tq, px, spare, pos)``, ``at`` the offset in si of the extended indices' indices in
    K (the identity for the step's own matrix), ``tq``, ``px`` of the spans of ``T_q`` and
    ``P_X`` (the extended step's), ``spare`` the spare cell's offset in ``A[0]``, ``pos``
    the offset of the positions in the banded ordering; all 0 where there is none (the
    first: whether there is one)."""
    ws = own(ws_)
    si = ws.si
    xm = si[SI_XMAP]
    if xm == 0:
        return (xm, xm, xm, xm, xm, xm, xm, xm, xm)
    N, n = si[xm + XM_N], si[xm + XM_SIZE]
    at = xm + XMAP_HEADER
    tq = at + 2 * N + n
    px = tq + 3 * (N + n)
    return (xm, at, N, si[xm + XM_KL], si[xm + XM_KU], tq, px, si[px + 3 * N], at + N + n)


#: None for a small model's workspace: its writes compile to plain stores
assembly_map = only_if(_assembly_map, "structured", None)


@hot
def newton_banded(ws_, N):
    """Full Newton: ``ws.R`` ← ``A⁻¹ ws.R`` through the banded LU of the permuted ``ws.A``,
    packed into band storage, or factored where the assembly wrote it (a map,
    :func:`assembly_map`). Returns 0, or non-zero when a pivot vanished."""
    ws = own(ws_)
    si, sb = ws.si, ws.sb
    kl = si[SI_A_KL]
    ku = si[SI_A_KU]
    perm = si[si[SI_A_PERM]: si[SI_A_PERM] + N]
    t = sb[si[SI_RHS]: si[SI_RHS] + N]
    if mapped(assembly_map(ws_)):
        ab = ws.A[0, :band_ld(kl, ku) * N]
    else:
        ab = sb[si[SI_A_BAND]: si[SI_A_BAND] + band_ld(kl, ku) * N]
        band_pack(ws.A, perm, ab, N, kl, ku)
    if band_factor(ab, ws.piv, N, kl, ku) != 0:
        return 1
    R = ws.R
    for i in range(N):
        t[i] = R[perm[i]]
    band_solve(ab, ws.piv, t, N, kl, ku)
    for i in range(N):
        R[perm[i]] = t[i]
    return 0


@hot_inline
def g_times(si, Gj, x, out, m):
    """``out[c] = (G_j x)_c`` over the pattern of G."""
    gp = si[SI_GPTR]
    gc = si[SI_GCOL]
    for c in range(m):
        acc = 0.0
        for k in range(si[gp + c], si[gp + c + 1]):
            a = si[gc + k]
            acc += Gj[c, a] * x[a]
        out[c] = acc


@hot_inline
def gt_times(si, Gj, y, out, scale, m):
    """``out += scale · G_jᵀ y`` over the pattern of G."""
    gp = si[SI_GPTR]
    gc = si[SI_GCOL]
    for c in range(m):
        e = scale * y[c]
        if e != 0.0:
            for k in range(si[gp + c], si[gp + c + 1]):
                a = si[gc + k]
                out[a] += Gj[c, a] * e


@hot
def schur_structured(ws_, W, h, m, J):
    """Build ``[h W_{jj'} G_j M̄⁻¹ G_{j'}ᵀ]`` over the pattern of ``G Gᵀ`` straight into its
    banded or sparse factor storage (diagonal ``M̄``: ``ws.Y[j']`` holds ``G_{j'} M̄⁻¹`` on the
    pattern of G) and factor it. Returns 0, or non-zero when a pivot vanished."""
    ws = own(ws_)
    si, G, Y = ws.si, ws.G, ws.Y
    Jm = J * m
    st = ws.sb[si[SI_SC_BAND]: si[SI_SC_BAND] + si[SI_SC_LEN]]
    gp = si[SI_GPTR]
    gc = si[SI_GCOL]
    sp = si[SI_SPTR]
    sc = si[SI_SCOL]
    nnz = si[sp + m]
    for k in range(si[SI_SC_LEN]):
        st[k] = 0.0
    for j in range(1, J + 1):
        for jp in range(J):
            w = h * W[j - 1, jp]
            if w == 0.0:
                continue
            dst = si[SI_SC_DST] + ((j - 1) * J + jp) * nnz
            for c in range(m):
                for k in range(si[sp + c], si[sp + c + 1]):
                    e = si[sc + k]
                    acc = 0.0
                    for kk in range(si[gp + c], si[gp + c + 1]):
                        a = si[gc + kk]
                        acc += G[j, c, a] * Y[jp, e, a]
                    st[si[dst + k]] = w * acc
    if si[SI_SC] == SOLVE_BANDED:
        return band_factor(st, ws.pivs, Jm, si[SI_SC_KL], si[SI_SC_KU])
    return sparse_factor(si, st, si[SI_SC_LU], Jm)


@hot_inline
def schur_solve_structured(ws, x, Jm):
    """``x`` (the impulse rows of ``ws.R``) ← ``Sc⁻¹ x`` with the factors of
    :func:`schur_structured`."""
    si, sb = ws.si, ws.sb
    perm = si[si[SI_SC_PERM]: si[SI_SC_PERM] + Jm]
    st = sb[si[SI_SC_BAND]: si[SI_SC_BAND] + si[SI_SC_LEN]]
    t = sb[si[SI_RHS]: si[SI_RHS] + Jm]
    for i in range(Jm):
        t[i] = x[perm[i]]
    if si[SI_SC] == SOLVE_BANDED:
        band_solve(st, ws.pivs, t, Jm, si[SI_SC_KL], si[SI_SC_KU])
    else:
        sparse_solve(si, st, si[SI_SC_LU], t, Jm)
    for i in range(Jm):
        x[perm[i]] = t[i]


@hot_inline
def g_sub(si, Gj, x, R, off, m):
    """``R[off + c] −= (G_j x)_c`` over the pattern of G."""
    gp = si[SI_GPTR]
    gc = si[SI_GCOL]
    for c in range(m):
        acc = 0.0
        for k in range(si[gp + c], si[gp + c + 1]):
            a = si[gc + k]
            acc += Gj[c, a] * x[a]
        R[off + c] -= acc


@hot
def mech_rows_sparse(ws_, j, m):
    """``ws.Y[j]`` = ``G_j M̄⁻¹`` on the pattern of G (diagonal ``M̄``; the rest of ``Y``
    stays zero in a structured workspace)."""
    ws = own(ws_)
    si = ws.si
    gp = si[SI_GPTR]
    gc = si[SI_GCOL]
    minv = ws.minv
    for c in range(m):
        for k in range(si[gp + c], si[gp + c + 1]):
            a = si[gc + k]
            ws.Y[j, c, a] = ws.G[j, c, a] * minv[a]


@hot
def gmg_factor(si, sb, G, Mc, m, piv):
    """Build ``G M⁻¹ Gᵀ`` (diagonal constant ``M`` in ``Mc``) over the pattern of ``G Gᵀ``
    into the projection's banded or sparse storage and factor it. Returns 0, or non-zero
    when a pivot vanished."""
    st = sb[si[SI_S_BAND]: si[SI_S_BAND] + si[SI_S_LEN]]
    gp = si[SI_GPTR]
    gc = si[SI_GCOL]
    sp = si[SI_SPTR]
    sc = si[SI_SCOL]
    dst = si[SI_S_DST]
    for k in range(si[SI_S_LEN]):
        st[k] = 0.0
    for c in range(m):
        for k in range(si[sp + c], si[sp + c + 1]):
            e = si[sc + k]
            acc = 0.0
            for kk in range(si[gp + c], si[gp + c + 1]):
                a = si[gc + kk]
                acc += G[c, a] * G[e, a] / Mc[a, a]
            st[si[dst + k]] = acc
    if si[SI_S] == SOLVE_BANDED:
        return band_factor(st, piv, m, si[SI_S_KL], si[SI_S_KU])
    return sparse_factor(si, st, si[SI_S_LU], m)


@hot
def gmg_solve(si, sb, x, m, piv):
    """``x`` (m,) ← ``(G M⁻¹ Gᵀ)⁻¹ x`` with the factors of :func:`gmg_factor`."""
    ip = si[si[SI_S_IPERM]: si[SI_S_IPERM] + m]
    perm = si[si[SI_S_PERM]: si[SI_S_PERM] + m]
    st = sb[si[SI_S_BAND]: si[SI_S_BAND] + si[SI_S_LEN]]
    t = sb[si[SI_RHS]: si[SI_RHS] + m]
    for c in range(m):
        t[ip[c]] = x[c]
    if si[SI_S] == SOLVE_BANDED:
        band_solve(st, piv, t, m, si[SI_S_KL], si[SI_S_KU])
    else:
        sparse_solve(si, st, si[SI_S_LU], t, m)
    for i in range(m):
        x[perm[i]] = t[i]


@hot
def project_structured(Mc, q1, P, p1, v1, G1, ws_, n, m, rheonomic, out):
    """The end projection of :func:`.step.end_momentum` for a diagonal constant mass with
    ``G M⁻¹ Gᵀ`` built over the pattern of ``G Gᵀ`` and factored banded or sparse
    (:func:`gmg_factor`): ``p1 = P − G1ᵀ η``, ``(G M⁻¹ Gᵀ) η = G M⁻¹ P (+ g_t in ws.gt if
    rheonomic)``, ``v1 = M⁻¹ p1``; then, over the pattern of G as well, ``out[S_GV]`` =
    max|G1 v1 + g_t| and ``ws.G[0]`` = G1 (the next step's start; zero outside the pattern
    in both)."""
    ws = own(ws_)
    si, sb = ws.si, ws.sb
    gp = si[SI_GPTR]
    gc = si[SI_GCOL]
    eta = ws.etaJ
    for a in range(n):
        v1[a] = P[a] / Mc[a, a]
    for c in range(m):
        acc = ws.gt[c] if rheonomic else 0.0
        for k in range(si[gp + c], si[gp + c + 1]):
            a = si[gc + k]
            acc += G1[c, a] * v1[a]
        eta[c] = acc
    if gmg_factor(si, sb, G1, Mc, m, ws.pivm) != 0:
        return SINGULAR_CONSTRAINTS
    gmg_solve(si, sb, eta, m, ws.pivm)
    for a in range(n):
        p1[a] = P[a]
    gt_times(si, G1, eta, p1, -1.0, m)
    for a in range(n):
        v1[a] = p1[a] / Mc[a, a]
    for a in range(n):
        if not (np.isfinite(p1[a]) and np.isfinite(v1[a])):
            return NONFINITE
    gv = 0.0
    G0 = ws.G[0]
    for c in range(m):
        acc = ws.gt[c]
        for k in range(si[gp + c], si[gp + c + 1]):
            a = si[gc + k]
            x = G1[c, a]
            acc += x * v1[a]
            G0[c, a] = x
        gv = max(gv, abs(acc))
    out[S_GV] = gv
    return OK


@hot
def mech_impulses_structured(ws_, Lc, Ainv, h, n, m, s, J):
    """The impulse part of :func:`.step._mech_solve` with the pattern of G: from the stage
    increments ``ws.U`` (``h (A⁻¹ ⊗ M̄⁻¹) r_E``), subtract ``C U`` from the constraint rows of
    ``ws.R``, solve the structured Schur complement for ``δη``, and add
    ``h (A⁻¹ ⊗ M̄⁻¹) B δη`` to ``ws.U``. Not inlined, so that the step of small models
    compiles to the code it had before."""
    ws = own(ws_)
    R, Z, U, Y, G = ws.R, ws.Z, ws.U, ws.Y, ws.G
    T = ws.fa
    sn = s * n
    for j in range(1, J + 1):
        for a in range(n):
            T[a] = 0.0
        for mu in range(1, s + 1):
            cl = Lc[mu, j]
            if cl != 0.0:
                for a in range(n):
                    T[a] += cl * U[mu - 1, a]
        g_sub(ws.si, G[j], T, R, sn + (j - 1) * m, m)
    schur_solve_structured(ws, R[sn:], J * m)
    for nu in range(s):
        for a in range(n):
            Z[nu, a] = 0.0
        for jp in range(J):
            cl = Lc[nu, jp]
            if cl != 0.0:
                gt_times(ws.si, Y[jp], R[sn + jp * m:], Z[nu], cl, m)
    for mu in range(s):
        for nu in range(s):
            c = h * Ainv[mu, nu]
            for a in range(n):
                U[mu, a] += c * Z[nu, a]


# what the step calls: compiled into it only for a workspace with a structured plan
newton_banded = only_if(newton_banded, "structured", 0)
schur_structured = only_if(schur_structured, "structured", 0)
mech_rows_sparse = only_if(mech_rows_sparse, "structured")
project_structured = only_if(project_structured, "structured", 0)
mech_impulses_structured = only_if(mech_impulses_structured, "structured")
