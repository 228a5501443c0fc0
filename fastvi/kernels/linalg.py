"""Small dense LU with partial pivoting, in place, no allocation.

Hand-written because the Newton matrices are small (tens to a few hundred rows) and the
step kernel must not allocate; numpy's ``solve`` would allocate on every call.
"""

import numpy as np

from .._numba import hot


@hot
def lu_factor(A, piv, N):
    """Factor the leading N×N block of ``A`` in place as P A = L U.

    Returns 0 on success, or ``k + 1`` if the pivot of column ``k`` is zero or not finite
    (the matrix is singular to working precision or holds NaN/inf).
    """
    for k in range(N):
        p = k
        big = abs(A[k, k])
        for i in range(k + 1, N):
            a = abs(A[i, k])
            if a > big:
                big = a
                p = i
        piv[k] = p
        if not (big > 0.0) or not np.isfinite(big):
            return k + 1
        if p != k:
            for j in range(N):
                t = A[k, j]
                A[k, j] = A[p, j]
                A[p, j] = t
        inv = 1.0 / A[k, k]
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
        b[i] = s / A[i, i]


@hot
def pivot_ratio(A, N):
    """min |U_kk| / max |U_kk| of a factored matrix: a cheap conditioning alarm."""
    lo = np.inf
    hi = 0.0
    for k in range(N):
        a = abs(A[k, k])
        lo = min(lo, a)
        hi = max(hi, a)
    return lo / hi if hi > 0.0 else 0.0
