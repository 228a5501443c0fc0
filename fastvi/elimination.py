r"""Orderings and symbolic factorisations of sparse patterns, once per model (issue 12).

NumPy and plain Python, run at planning time (:func:`fastvi.structure.plan`) on the
pattern of a structurally symmetric matrix; the numeric factorisation that uses the result
is :mod:`fastvi.kernels.sparse_lu`.

* :func:`minimum_degree` — the greedy minimum-degree ordering on the elimination graph
  (eliminate a vertex of fewest neighbours, join its neighbours into a clique): for a tree
  of bodies it eliminates from the leaves inward and creates no fill; SciPy offers no
  such ordering for a symmetric pattern (only reverse Cuthill–McKee, which minimises the
  band, not the fill).
* :func:`symbolic_lu` — the elimination game in a given order: the filled pattern, a
  position for each of its entries in a flat value array, and, for each pivot ``k``, the
  entries of ``L_k`` (column ``k`` below the diagonal), ``U_k`` (row ``k`` right of it) and
  the targets of the update ``A_ij −= l_ik u_kj``. Without row interchanges the filled
  pattern of ``L + U`` is that of the Cholesky factor of the symmetrised pattern.
"""

from __future__ import annotations

import heapq
from collections import namedtuple

import numpy as np

__all__ = ["minimum_degree", "symbolic_lu", "Symbolic"]

Symbolic = namedtuple("Symbolic", ["nnz", "flops", "arrays", "position"])
Symbolic.__doc__ = """The symbolic LU of :func:`symbolic_lu`: ``nnz`` entries of the filled
pattern, ``flops`` of the numeric factorisation (one multiply–add per update, one division
per entry of L), ``arrays`` (``diag, lptr, lrow, lpos, uptr, ucol, upos, wptr, wpos``: the
``LU_*`` arrays of :mod:`fastvi.kernels.layout`, int64) and ``position(i, j)`` → index in
the value array of entry (i, j) of the permuted matrix (−1 outside the filled pattern)."""


def _neighbours(P):
    P = np.asarray(P, dtype=bool)
    if P.ndim != 2 or P.shape[0] != P.shape[1]:
        raise ValueError(f"a pattern must be a square boolean matrix, got shape {P.shape}")
    S = P | P.T
    return [set(np.flatnonzero(S[i])) - {i} for i in range(S.shape[0])]


def minimum_degree(P) -> np.ndarray:
    """A minimum-degree elimination order of the symmetrised pattern ``P`` (N × N bool).

    Ties go to the lowest index, so the order is deterministic. Returns ``perm`` (int64):
    row ``k`` of the permuted matrix is row ``perm[k]`` of ``P``. Cost O(Σ deg²) in Python:
    milliseconds for the few thousand rows of the models here.
    """
    adj = _neighbours(P)
    N = len(adj)
    heap = [(len(adj[i]), i) for i in range(N)]
    heapq.heapify(heap)
    done = np.zeros(N, dtype=bool)
    order = []
    while heap:
        d, i = heapq.heappop(heap)
        if done[i] or d != len(adj[i]):
            continue  # a stale entry: the degree changed since it was pushed
        done[i] = True
        order.append(i)
        nb = adj[i]
        for a in nb:
            adj[a].discard(i)
            adj[a] |= nb - {a}
        for a in nb:
            heapq.heappush(heap, (len(adj[a]), a))
    return np.asarray(order, dtype=np.int64)


def symbolic_lu(P, perm) -> Symbolic:
    """The symbolic LU without row interchanges of ``P[perm][:, perm]`` (see the module
    docstring). ``P`` is symmetrised first; the diagonal is always in the pattern."""
    perm = np.asarray(perm, dtype=np.int64)
    P = np.asarray(P, dtype=bool)
    N = P.shape[0]
    if sorted(perm.tolist()) != list(range(N)):
        raise ValueError(f"`perm` must be a permutation of 0 … {N - 1}")
    adj = _neighbours(P[np.ix_(perm, perm)])
    higher = []
    for k in range(N):  # the elimination game: k's later neighbours become a clique
        hk = sorted(j for j in adj[k] if j > k)
        higher.append(hk)
        for a in hk:
            adj[a].update(hk)
            adj[a].discard(a)
    pos = {}
    for k in range(N):
        pos[(k, k)] = len(pos)
        for j in higher[k]:
            pos[(k, j)] = len(pos)
            pos[(j, k)] = len(pos)
    diag = np.array([pos[(k, k)] for k in range(N)], dtype=np.int64)
    ptr = np.concatenate(([0], np.cumsum([len(h) for h in higher]))).astype(np.int64)
    idx = np.array([j for h in higher for j in h], dtype=np.int64)
    lpos = np.array([pos[(j, k)] for k in range(N) for j in higher[k]], dtype=np.int64)
    upos = np.array([pos[(k, j)] for k in range(N) for j in higher[k]], dtype=np.int64)
    wptr = np.concatenate(([0], np.cumsum([len(h) ** 2 for h in higher]))).astype(np.int64)
    wpos = np.array([pos[(i, j)] for k in range(N) for i in higher[k] for j in higher[k]],
                    dtype=np.int64)
    arrays = dict(diag=diag, lptr=ptr, lrow=idx, lpos=lpos, uptr=ptr, ucol=idx, upos=upos,
                  wptr=wptr, wpos=wpos)
    flops = int(sum(len(h) + len(h) ** 2 for h in higher))
    return Symbolic(len(pos), flops, arrays, lambda i, j: pos.get((int(i), int(j)), -1))
