"""The small dense solvers of the kernels against NumPy: LU with the reciprocal pivots on
its diagonal, its inlined copies, and the Gauss–Jordan inverse of the Schur complement."""

import numpy as np
import pytest
from numba import njit

from fastvi.kernels.linalg import invert, lu_factor, lu_factor_small, lu_solve, lu_solve_small


@njit
def _small(A, piv, b, N):
    st = lu_factor_small(A, piv, N)
    if st == 0:
        lu_solve_small(A, piv, b, N)
    return st


@njit
def _inverse(A, piv, N):
    return invert(A, piv, N)


def _matrices(N, count=20, seed=0):
    rng = np.random.default_rng(seed)
    for k in range(count):
        A = rng.normal(size=(N, N))
        if k % 2:  # a small leading pivot forces row interchanges
            A[0, 0] = 1e-9
        yield A


@pytest.mark.parametrize("N", [1, 2, 3, 6, 12])
def test_lu_solves_like_numpy(N):
    rng = np.random.default_rng(N)
    for A in _matrices(N):
        b = rng.normal(size=N)
        want = np.linalg.solve(A, b)
        scale = np.abs(want).max() * np.linalg.cond(A)
        F, piv, x = A.copy(), np.zeros(N, dtype=np.int64), b.copy()
        assert lu_factor(F, piv, N) == 0
        # the diagonal holds 1/U_kk: P A = L U with U's diagonal the reciprocals
        L = np.tril(F, -1) + np.eye(N)
        U = np.triu(F, 1) + np.diag(1.0 / np.diag(F))
        PA = A.copy()
        for k in range(N):
            PA[[k, piv[k]]] = PA[[piv[k], k]]
        assert np.abs(L @ U - PA).max() < 1e-12 * np.abs(A).max() * N
        lu_solve(F, piv, x, N)
        assert np.abs(x - want).max() < 1e-13 * scale
        F2, x2 = A.copy(), b.copy()
        assert _small(F2, piv, x2, N) == 0
        assert np.array_equal(x2, x)  # the inlined copy is the same arithmetic


@pytest.mark.parametrize("N", [1, 2, 4, 6, 9])
def test_invert_inverts_like_numpy(N):
    for A in _matrices(N, seed=N):
        want = np.linalg.inv(A)
        Ai, piv = A.copy(), np.zeros(N, dtype=np.int64)
        assert _inverse(Ai, piv, N) == 0
        assert np.abs(Ai - want).max() < 1e-13 * np.abs(want).max() * np.linalg.cond(A)


@pytest.mark.parametrize("solver", ["lu", "invert"])
def test_singular_and_non_finite_matrices_are_reported(solver):
    def run(A):
        piv = np.zeros(3, dtype=np.int64)
        if solver == "lu":
            return lu_factor(A, piv, 3)
        return _inverse(A, piv, 3)

    A = np.arange(9.0).reshape(3, 3)  # rank 2: the third pivot vanishes
    A[2] = A[0] + A[1]
    assert run(A) == 3
    B = np.eye(3)
    B[1, 1] = np.nan
    assert run(B) == 2
