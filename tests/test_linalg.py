"""The small dense solvers of the kernels against NumPy: LU with the reciprocal pivots on
its diagonal, its inlined copies, and the Gauss–Jordan inverse of the Schur complement."""

import numpy as np
import pytest

# the helpers are compiled with the kernels' own options, as a kernel inlining these would be
from fastvi._numba import njit
from fastvi.kernels.linalg import (PIVOT_MIN, invert, invert_unpivoted, lu_factor, lu_factor_small,
                                   lu_solve, lu_solve_small)
from fastvi.tables import method


@njit
def _small(A, piv, b, N):
    st = lu_factor_small(A, piv, N)
    if st == 0:
        lu_solve_small(A, piv, b, N)
    return st


@njit
def _inverse(A, piv, N):
    return invert(A, piv, N)


@njit
def _inverse_unpivoted(A, N):
    return invert_unpivoted(A, N)


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


def _schur_like(name, m=2, n=4, seed=0):
    """A Schur complement of the mechanics iteration, ``[h W_{j−1,j'} G_j M⁻¹ G_{j'}ᵀ]``, with
    the method's own W and Jacobians G_j of a moving configuration (random rows plus a drift
    along the step: neighbouring constraint points see nearby Jacobians)."""
    W = method(name).kernel_tables.W
    J = W.shape[0]
    rng = np.random.default_rng(seed)
    G0, dG = rng.normal(size=(m, n)), 0.2 * rng.normal(size=(m, n))
    Minv = np.diag(1.0 / rng.uniform(0.5, 2.0, size=n))
    G = [G0 + (j / J) * dG for j in range(J + 1)]
    S = np.zeros((J * m, J * m))
    for j in range(1, J + 1):
        for jp in range(J):
            S[(j - 1) * m:j * m, jp * m:(jp + 1) * m] = 0.01 * W[j - 1, jp] * G[j] @ Minv @ G[jp].T
    return S


@pytest.mark.parametrize("name", ["P1L-Q2G", "P2L-Q3G", "P3L-Q4G", "P4L-Q4G", "P5L-Q6G"])
def test_unpivoted_inverse_of_the_schur_complements_like_numpy(name):
    """The methods' Schur complements need no row interchanges: the pivot-free inverse is
    accepted and as accurate as NumPy's, for every default Lobatto method."""
    for seed in range(10):
        S = _schur_like(name, seed=seed)
        N = S.shape[0]
        want = np.linalg.inv(S)
        Si = S.copy()
        assert _inverse_unpivoted(Si, N) == 0
        assert np.abs(Si - want).max() < 1e-13 * np.abs(want).max() * np.linalg.cond(S)


def test_unpivoted_inverse_gives_up_on_small_pivots():
    """A pivot below PIVOT_MIN of the largest entry (or NaN) is refused; a matrix that only
    partial pivoting inverts accurately is then left to ``invert``."""
    A = np.array([[1e-9, 1.0], [1.0, 1.0]])
    assert _inverse_unpivoted(A.copy(), 2) == 1
    B = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 1.0], [0.0, 2.0, 1.0 + 0.5 * PIVOT_MIN]])
    assert _inverse_unpivoted(B.copy(), 3) == 3  # the third pivot is 0.5 PIVOT_MIN × max
    C = np.eye(3)
    C[1, 1] = np.nan
    assert _inverse_unpivoted(C, 3) == 2
    D = np.eye(2) * 3.0  # a pivot just above the floor is taken
    D[1, 1] = 3.0 * PIVOT_MIN * 1.01
    Di = D.copy()
    assert _inverse_unpivoted(Di, 2) == 0
    assert np.allclose(Di, np.linalg.inv(D), rtol=1e-15)
