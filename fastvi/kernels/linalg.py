"""Small dense LU and inverse with partial pivoting, in place, no allocation.

Hand-written because the Newton matrices are small (tens to a few hundred rows) and the
step kernel must not allocate; numpy's ``solve`` would allocate on every call.

The factors keep the *reciprocals* of the pivots on the diagonal: the back substitution
multiplies instead of dividing, and its divisions sit on the chain of dependent
operations that sets a small solve's time. The pivot search selects without branching:
which row wins is data, and a mispredicted branch per row costs more than the
comparison. ``lu_factor_small`` and ``lu_solve_small`` are the same functions inlined
into their callers, for the systems of a constraint's or a coordinate's size, whose
size is a compile-time constant in the size-specialized step (and there unrolled).
``invert_unpivoted`` inverts without row interchanges the matrices whose pivots are known
to stay large (the mechanics iteration's Schur complement) and says when one is not.
"""

import numpy as np

from .._numba import hot, hot_inline


@hot_inline
def _pivot(A, piv, k, N):
    """Partial pivoting at column ``k``: the row of the largest ``|A[i, k]|``, i ≥ k, swapped
    into row k (its index in ``piv[k]``), found with selects, not branches. Returns False
    for a zero or non-finite pivot."""
    p = k
    big = abs(A[k, k])
    for i in range(k + 1, N):
        a = abs(A[i, k])
        better = a > big
        big = a if better else big
        p = i if better else p
    piv[k] = p
    if not (big > 0.0) or not np.isfinite(big):
        return False
    if p != k:
        for j in range(N):
            t = A[k, j]
            A[k, j] = A[p, j]
            A[p, j] = t
    return True


@hot
def lu_factor(A, piv, N):
    """Factor the leading N×N block of ``A`` in place as P A = L U, with ``1/U_kk`` stored
    on the diagonal (for :func:`lu_solve`).

    Returns 0 on success, or ``k + 1`` if the pivot of column ``k`` is zero or not finite
    (the matrix is singular to working precision or holds NaN/inf).
    """
    for k in range(N):
        if not _pivot(A, piv, k, N):
            return k + 1
        inv = 1.0 / A[k, k]
        A[k, k] = inv
        for i in range(k + 1, N):
            A[i, k] *= inv
        for i in range(k + 1, N):
            f = A[i, k]
            if f != 0.0:
                for j in range(k + 1, N):
                    A[i, j] -= f * A[k, j]
    return 0


@hot
def lu_solve(A, piv, b, N):
    """Solve with the factors of :func:`lu_factor`; ``b`` (length ≥ N) is overwritten."""
    for k in range(N):
        p = piv[k]
        if p != k:
            t = b[k]
            b[k] = b[p]
            b[p] = t
    for i in range(N):
        s = b[i]
        for j in range(i):
            s -= A[i, j] * b[j]
        b[i] = s
    for i in range(N - 1, -1, -1):
        s = b[i]
        for j in range(i + 1, N):
            s -= A[i, j] * b[j]
        b[i] = s * A[i, i]


@hot_inline
def _eliminate(A, k, N):
    """One Gauss–Jordan step in place at the pivot ``A[k, k]``: row k scaled by its
    reciprocal, column k cleared in every other row; the cleared column keeps the inverse's
    column as it builds up."""
    inv = 1.0 / A[k, k]
    A[k, k] = 1.0
    for j in range(N):
        A[k, j] *= inv
    for i in range(N):
        if i != k:
            f = A[i, k]
            A[i, k] = 0.0
            for j in range(N):
                A[i, j] -= f * A[k, j]


@hot_inline
def invert(A, piv, N):
    """Overwrite the leading N×N block of ``A`` with its inverse (Gauss–Jordan, partial
    pivoting, in place). Returns 0, or ``k + 1`` for a zero or non-finite pivot.

    Inlined, so that a caller with a compile-time ``N`` (the size-specialized step) gets it
    unrolled; no zero is skipped (the Schur complements it inverts are dense)."""
    for k in range(N):
        if not _pivot(A, piv, k, N):
            return k + 1
        _eliminate(A, k, N)
    # the rows were interchanged in place, so this is the inverse of P A; A⁻¹ = (P A)⁻¹ P
    # is it with the interchanges undone on the columns, the last one first
    for k in range(N - 1, -1, -1):
        p = piv[k]
        if p != k:
            for i in range(N):
                t = A[i, k]
                A[i, k] = A[i, p]
                A[i, p] = t
    return 0


#: :func:`invert_unpivoted` gives up, for :func:`invert`, on a pivot below this fraction of
#: the matrix's largest entry: without row interchanges the error of the inverse grows like
#: the inverse of that ratio
PIVOT_MIN = 1e-3


@hot_inline
def invert_unpivoted(A, N):
    """Overwrite the leading N×N block of ``A`` with its inverse by Gauss–Jordan without row
    interchanges, for matrices whose diagonal pivots are known to stay large (the mechanics
    iteration's Schur complement). Returns 0, or ``k + 1`` when the pivot of column ``k`` is
    below ``PIVOT_MIN`` times the largest ``|A_ij|`` or not finite: ``A`` is then left
    part-way, to be rebuilt for :func:`invert`.

    The pivot search and the row interchanges (data-dependent, so never unrolled away) were
    a third of :func:`invert`'s time on the 4 × 4 to 8 × 8 Schur complements."""
    big = 0.0
    for i in range(N):
        for j in range(N):
            big = max(big, abs(A[i, j]))
    floor = PIVOT_MIN * big
    for k in range(N):
        pk = A[k, k]
        if not (abs(pk) > floor) or not np.isfinite(pk):
            return k + 1
        _eliminate(A, k, N)
    return 0


lu_factor_small = hot_inline(lu_factor.py_func)
lu_solve_small = hot_inline(lu_solve.py_func)


#: γ of :func:`augmented_mass` relative to the smallest non-zero diagonal entry of M
AUGMENT_SCALE = 0.01


@hot
def augmented_mass(M, G, out, n, m):
    r"""``out = M + Gᵀ W G`` with ``W = diag(γ / |G_c|²)``, ``γ`` = ``AUGMENT_SCALE`` times the
    smallest non-zero ``M_aa``.

    For a mass matrix that is only positive *semi*definite (a lamina's or a slender rod's
    director inertia) but definite on ``ker G``: ``M̄`` is then definite on the whole space
    and equals ``M`` on ``ker G``, so a solve of the saddle-point system

    .. math:: M̄ v + Gᵀ η = P, \quad G v = c

    gives the same ``v`` as one with ``M`` (only the multiplier moves, by ``W c``), and
    an iteration matrix built from ``M̄`` converges to the same solution. Each row of
    ``G`` is scaled to unit length so that ``γ`` alone sets the size of the added term,
    whatever the units of the constraints. A small ``γ`` keeps the iteration close to
    Newton's where ``G`` varies over the step: with ``γ`` the largest inertia the heavy
    top took 8.7 iterations a step, with this one 2.9 (``docs/method.md`` §12).
    """
    gamma = _augment_scale(M, n)
    for a in range(n):
        for b in range(n):
            out[a, b] = M[a, b]
    for c in range(m):
        w = _augment_weight(G, c, gamma, n)
        if w == 0.0:
            continue
        for a in range(n):
            ga = w * G[c, a]
            if ga != 0.0:
                for b in range(n):
                    out[a, b] += ga * G[c, b]


@hot
def augment_weights(M, G, w, n, m):
    """``w`` (m,) = the diagonal of :func:`augmented_mass`'s ``W``, zero for a zero row of
    ``G``: the linearised step's ``∂(M̄ v)/∂q = Gᵀ W H_v`` where ``G v = 0``."""
    gamma = _augment_scale(M, n)
    for c in range(m):
        w[c] = _augment_weight(G, c, gamma, n)


@hot_inline
def _augment_scale(M, n):
    """``γ``: ``AUGMENT_SCALE`` times the smallest positive diagonal entry of ``M``."""
    gamma = np.inf
    for a in range(n):
        if M[a, a] > 0.0:
            gamma = min(gamma, M[a, a])
    return gamma * AUGMENT_SCALE


@hot_inline
def _augment_weight(G, c, gamma, n):
    """``γ / |G_c|²`` (0 for a zero row)."""
    norm2 = 0.0
    for a in range(n):
        norm2 += G[c, a] * G[c, a]
    if norm2 == 0.0:
        return 0.0
    return gamma / norm2
