r"""Sparse LU with static pivots and a symbolic factorisation computed once (issue 12).

For patterns a band does not fit — trees of bodies, mechanisms with a hub — the Schur
complement of the mechanics iteration and the projection ``G M⁻¹ Gᵀ`` are factored as
``A = L U`` in a fill-reducing order (minimum degree, :mod:`fastvi.elimination`) fixed at
planning time, without row interchanges. Every index the elimination needs is computed
once in NumPy and stored in ``ws.si`` under a descriptor (``LU_*`` of :mod:`.layout`): the
factor storage is one flat array of the filled pattern's values; pivot ``k`` divides the
entries of its column below the diagonal (``L_k``) and subtracts their products with the
entries of its row right of the diagonal (``U_k``) at precomputed positions. The kernels
then do the arithmetic of the factorisation and nothing else: no search, no allocation.

Why static pivots are safe where this is used: ``G M⁻¹ Gᵀ`` is symmetric positive definite
for a full-rank ``G`` (any symmetric ordering has positive pivots), and the Schur
complement ``[h W_{jj'} G_j M̄⁻¹ G_{j'}ᵀ]`` is ordered by constraint with the ``J`` impulses
of a constraint adjacent in the order of the table ``W`` (nearly lower triangular with a
diagonal well away from zero), so each pivot is that of ``W``'s LU times a pivot of an SPD
matrix. A pivot that is zero or not finite returns a failure code as the banded LU does:
the mechanics iteration then falls back to the full Newton, the projection reports
singular constraints.
"""

import numpy as np

from .._numba import hot
from .layout import LU_DIAG, LU_LPOS, LU_LPTR, LU_LROW, LU_UCOL, LU_UPOS, LU_UPTR, LU_WPOS, LU_WPTR

__all__ = ["sparse_factor", "sparse_solve"]


@hot
def sparse_factor(si, F, o, N):
    """Factor in place the values ``F`` of the filled pattern of the descriptor at
    ``si[o:]`` (``L`` unit lower, ``U`` upper). Returns 0, or ``k + 1`` if pivot ``k`` is
    zero or not finite."""
    dg = si[o + LU_DIAG]
    lp = si[o + LU_LPTR]
    lq = si[o + LU_LPOS]
    up = si[o + LU_UPTR]
    uq = si[o + LU_UPOS]
    wp = si[o + LU_WPTR]
    wq = si[o + LU_WPOS]
    for k in range(N):
        piv = F[si[dg + k]]
        if not (piv != 0.0 and np.isfinite(piv)):
            return k + 1
        inv = 1.0 / piv
        l0 = si[lp + k]
        l1 = si[lp + k + 1]
        u0 = si[up + k]
        nu = si[up + k + 1] - u0
        w = si[wp + k]
        for a in range(l0, l1):
            p = si[lq + a]
            F[p] *= inv
            lik = F[p]
            if lik != 0.0:
                for b in range(nu):
                    F[si[wq + w + b]] -= lik * F[si[uq + u0 + b]]
            w += nu
    return 0


@hot
def sparse_solve(si, F, o, x, N):
    """``x`` (length ≥ N) ← ``U⁻¹ L⁻¹ x`` with the factors of :func:`sparse_factor`."""
    dg = si[o + LU_DIAG]
    lp = si[o + LU_LPTR]
    lr = si[o + LU_LROW]
    lq = si[o + LU_LPOS]
    up = si[o + LU_UPTR]
    uc = si[o + LU_UCOL]
    uq = si[o + LU_UPOS]
    for k in range(N):
        xk = x[k]
        if xk != 0.0:
            for a in range(si[lp + k], si[lp + k + 1]):
                x[si[lr + a]] -= F[si[lq + a]] * xk
    for k in range(N - 1, -1, -1):
        acc = x[k]
        for b in range(si[up + k], si[up + k + 1]):
            acc -= F[si[uq + b]] * x[si[uc + b]]
        x[k] = acc / F[si[dg + k]]
