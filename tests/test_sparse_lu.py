"""The sparse LU of issue 12: minimum-degree ordering, symbolic factorisation, numeric kernels
(``fastvi.elimination``, ``fastvi.kernels.sparse_lu``), checked against NumPy's dense solve."""

import numpy as np
import pytest

from fastvi.elimination import minimum_degree, symbolic_lu
from fastvi.kernels import layout as lay
from fastvi.kernels.sparse_lu import sparse_factor, sparse_solve
from fastvi.structure import _LU_ARRAYS


def _descriptor(sym):
    """``si`` holding a sparse LU descriptor at offset 0, as :func:`fastvi.structure.plan`
    lays it out."""
    hdr = np.zeros(lay.LU_HEADER, dtype=np.int64)
    parts, off = [hdr], lay.LU_HEADER
    for slot, name in _LU_ARRAYS.items():
        hdr[slot] = off
        parts.append(sym.arrays[name])
        off += len(sym.arrays[name])
    return np.concatenate(parts)


def _factor_and_solve(A, P, perm, b):
    sym = symbolic_lu(P, perm)
    si = _descriptor(sym)
    N = A.shape[0]
    F = np.zeros(sym.nnz)
    Ap = A[np.ix_(perm, perm)]
    for i, j in zip(*np.nonzero(Ap)):
        pos = sym.position(i, j)
        assert pos >= 0, "an entry of the matrix outside the filled pattern"
        F[pos] = Ap[i, j]
    st = sparse_factor(si, F, 0, N)
    x = b[perm].copy()
    if st == 0:
        sparse_solve(si, F, 0, x, N)
    y = np.empty(N)
    y[perm] = x
    return st, y, sym


def _random_pattern(rng, N, density):
    P = rng.random((N, N)) < density
    return P | P.T | np.eye(N, dtype=bool)


@pytest.mark.parametrize("N,density", [(1, 1.0), (7, 0.4), (60, 0.05), (150, 0.02)])
def test_sparse_lu_solves_like_numpy(N, density):
    rng = np.random.default_rng(N)
    P = _random_pattern(rng, N, density)
    A = np.where(P, rng.standard_normal((N, N)), 0.0)
    A[np.diag_indices(N)] += 2.0 * np.sqrt(P.sum(axis=1))  # static pivots: well away from 0
    if N > 1:
        A[0, -1] = 0.0  # an unsymmetric value in a symmetric pattern
    b = rng.standard_normal(N)
    st, x, _ = _factor_and_solve(A, P, minimum_degree(P), b)
    assert st == 0
    ref = np.linalg.solve(A, b)
    # measured ≤ 2e-15 relative
    assert np.max(np.abs(x - ref)) <= 1e-12 * np.max(np.abs(ref))


def test_sparse_lu_reports_a_zero_pivot():
    N = 6
    A = np.diag(np.arange(1.0, N + 1)) + np.diag(np.ones(N - 1), 1) + np.diag(np.ones(N - 1), -1)
    A[3, :] = 0.0
    A[:, 3] = 0.0
    P = A != 0.0
    st, _, _ = _factor_and_solve(A, P | np.eye(N, dtype=bool), np.arange(N), np.ones(N))
    assert st == 4  # pivot of row 3, 1-based


def _star_of_paths(branches, length):
    """The graph of a tree: a hub (0) with ``branches`` paths of ``length`` vertices."""
    N = 1 + branches * length
    P = np.eye(N, dtype=bool)
    for b in range(branches):
        prev = 0
        for k in range(length):
            v = 1 + b * length + k
            P[v, prev] = P[prev, v] = True
            prev = v
    return P


def test_minimum_degree_eliminates_a_tree_without_fill():
    P = _star_of_paths(6, 5)
    perm = minimum_degree(P)
    assert sorted(perm) == list(range(P.shape[0]))
    sym = symbolic_lu(P, perm)
    # a tree eliminated from its leaves inward: the filled pattern is the pattern itself
    assert sym.nnz == P.sum()
    # the natural order (hub first) joins the hub's 6 neighbours into a clique, and the fill
    # spreads down the branches from there…
    natural = symbolic_lu(P, np.arange(P.shape[0]))
    assert natural.nnz >= P.sum() + 6 * 5
    # … and the flop count reflects it
    assert sym.flops < natural.flops


def test_symbolic_lu_rejects_a_bad_permutation():
    with pytest.raises(ValueError, match="`perm` must be a permutation"):
        symbolic_lu(np.eye(3, dtype=bool), [0, 0, 1])
    with pytest.raises(ValueError, match="square"):
        minimum_degree(np.ones((2, 3), dtype=bool))
