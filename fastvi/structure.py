r"""Sparsity of a model and the plan of a step's linear solves (issue 12).

Once per model, method and parameter vector, in NumPy:

1. **The pattern.** The non-zeros of ``G`` and of the full Newton matrix are detected by
   evaluating the model at ``PATTERN_STATES`` random states (configurations, velocities,
   impulses and unknowns drawn from a normal distribution, not consistent ones: a
   structural zero does not depend on the state) and taking the union. The Newton matrix
   ``∂R/∂X`` is not assembled for this: column ``k`` holds the rows of the step's residual
   that change when the unknown ``X_k`` moves by an amount of order one
   (:func:`fastvi.kernels.step.residual_dependence`; the residual is evaluated exactly, so
   a row that does not depend on ``X_k`` comes out the same, bit for bit). The blocks that
   are ``G`` itself and the constraint Hessian's are added as the kernel forms them, since
   an entry at round-off of an analytic zero (a rotation's arithmetic leaves 1e-18) does
   not move a residual of order one. The pattern is then exactly what the kernel's
   assembly writes, finite-difference Hessians included (a coordinate on which a
   derivative does not depend gives an exact zero difference), and only the residual is
   compiled for it, not the Newton matrix (a third of a structured model's first compile).
   A zero that is only accidental at one random state is caught by the other states
   (probability zero otherwise). A model may declare
   the pattern of ``G`` instead (``Model(constraint_jacobian_pattern=)``, verified by
   :meth:`fastvi.Model.check`); its callback then writes only those entries. From ``G``: the
   patterns of ``G Gᵀ`` (the projection) and of the Schur complement of the mechanics
   iteration.
2. **The orderings.** SciPy's reverse Cuthill–McKee on each symmetrised pattern, and the
   lower/upper bandwidths of the permuted matrix; for the Schur complement and the
   projection also a minimum-degree order of the constraints and the symbolic LU in it
   (:mod:`fastvi.elimination`).
3. **The choice.** Of the dense LU, the banded LU (:mod:`fastvi.kernels.banded`) and — for
   the Schur complement and the projection — the sparse LU with static pivots
   (:mod:`fastvi.kernels.sparse_lu`), the one of fewest flops, the sparse one's weighted by
   ``SPARSE_COST`` and every structured one only from ``BAND_MIN_ROWS`` rows (the measured
   crossovers, ``docs/decisions/0004-sparse-lu.md``): every small model keeps the dense path, bit for
   bit, and is not even analysed. A chain is banded (its band is as thin as its fill);
   a tree of bodies or a ladder of loops is sparse (a hub or a rung widens the band, not
   the fill). The Schur complement and the projection use the pattern
   of ``G`` only with a diagonal constant mass (``M⁻¹`` is otherwise dense).

4. **Grouped differences.** A model without an exact ``constraint_hessian`` gets Curtis–
   Powell–Reid column groups of ``Σ η_i ∇²g_i`` (pattern ``Gᵀ G``): the full Newton
   matrix differences the Jacobian callback twice per group, not per coordinate (6 groups
   for a chain of any length), with the column-by-column result bit for bit
   (:func:`fastvi.kernels.step.fd_constraint_hessian_grouped`).

Why safe: the full Newton and the mechanics iteration only *solve for an increment* — a
non-zero outside the detected band would slow their convergence, never change the
solution, whose residual is evaluated exactly. The projection ``G M⁻¹ Gᵀ η = G M⁻¹ P`` is
exact arithmetic on the pattern of ``G``. A *detected* pattern cannot miss an entry the
callback writes at three random states (a structural zero does not depend on the state). A
*declared* pattern is taken as it is — the callback writes only its entries, and ``|G v|``
is then evaluated over it too — so it is verified where the model is: by
:meth:`fastvi.Model.check` and the automatic check of the first integration, which name a
non-zero written outside it and a derivative finite differences find where it says zero
(``check=False`` skips that, at the user's risk).
"""

from __future__ import annotations

import weakref
from collections import namedtuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import reverse_cuthill_mckee

from ._numba import quiet
from .elimination import minimum_degree, symbolic_lu
from .kernels import layout as lay
from .kernels.banded import band_ld

__all__ = ["Plan", "plan", "workspace", "detect_pattern", "SOLVERS", "PATTERN_STATES"]

#: random states whose non-zeros are united into the detected pattern
PATTERN_STATES = 3
#: a system is solved banded from this many rows: the crossovers measured on chain(N),
#: ``P2L-Q3G``, side by side (docs/benchmarks.md, "Large mechanisms"): the full Newton step
#: 0.95× at 24 rows, 1.23× at 48; the mechanics step (Schur complement and products with
#: the pattern of G) 0.94× at J m = 12, 1.12× at 16; the projection 0.9× at m = 6, 1.1× at 8
BAND_MIN_ROWS = dict(newton=36, schur=16, projection=8)
#: … and only if the banded factorisation's flop count ``N (kl + 1)(kl + ku + 1)`` is below
#: the dense one's ``N³/3`` by this factor (a pattern that fills the band stays dense)
BAND_GAIN = 1.0
#: the sparse LU's flop count is weighted by this against the banded and dense ones (its
#: indirect addressing): measured on chain(N) and tree(b, L), docs/decisions/0004-sparse-lu.md
SPARSE_COST = 4.0
#: the ``solver`` choices: automatic, or forced for every system (for tests and benchmarks)
SOLVERS = ("auto", "dense", "banded", "sparse")

Plan = namedtuple("Plan", ["si", "sb", "solvers", "bandwidths", "patterns"])
Plan.__doc__ = """A step's linear-solve plan: the workspace arrays ``si``, ``sb`` and, for
people, ``solvers`` / ``bandwidths`` ({"newton", "schur", "projection"} →
"dense"/"banded"/"sparse", (kl, ku) after RCM) and the detected ``patterns`` ({"G",
"newton"} → boolean arrays)."""

#: the plans memoised per model (a model's plan depends on its callbacks, fixed at
#: construction): dropped with the model
_PLANS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def detect_pattern(model, meth, prm=None, n_states: int = PATTERN_STATES, seed: int = 12):
    """Boolean non-zero patterns ``{"G": (m, n), "newton": (N, N)}``, the union over
    ``n_states`` random states (see the module docstring); ``G``'s is the model's
    ``constraint_jacobian_pattern`` where it declares one."""
    from .kernels.step import residual_dependence

    prm = model.params if prm is None else np.ascontiguousarray(prm, dtype=np.float64)
    rng = np.random.default_rng(seed)
    n, m, s, J = model.n, model.m, meth.s, meth.J
    N = s * n + J * m
    md = model.kernel_data(prm)
    # the residual alone: no full Newton's matrix
    ws = lay.make_workspace(n, m, s, meth.r, J, frozenset(lay.NEWTON_FIELDS))
    PG = np.zeros((m, n), dtype=bool)
    PA = np.zeros((N, N), dtype=bool)
    R0 = np.zeros(N)
    declared = model.constraint_jacobian_pattern  # checked by Model.check, taken as it is
    if declared is not None and m:
        # the residual's Gᵀη over G's pattern, as a structured step forms it: O(nnz(G)) a
        # residual, not O(m n), and the same rows change (outside the pattern G is zero)
        ws = ws._replace(si=_g_pattern_plan(declared))
    exact_hessian = "constraint_hessian" in model.callbacks
    tabs = meth.kernel_tables
    for _ in range(n_states):
        q = rng.standard_normal(n)
        if m:
            G0 = model.constraint_jacobian_value(q, prm)
            PG |= G0 != 0.0 if declared is None else declared
            ws.G[0, :m] = G0  # G at q_k: the step kernel sets it before Newton
        ws.X[:] = 0.1 * rng.standard_normal(N)
        p = rng.standard_normal(n)
        # moves of order one (a normal, away from zero): far above the residual's round-off
        dx = rng.standard_normal(N)
        dx += np.copysign(0.5, dx)
        with quiet():
            residual_dependence(md, tabs, 0.01, q, p, ws, dx, R0, PA)
        if m:
            _constraint_blocks(PA, ws.G, tabs.Lc, n, m, s, J)
            if exact_hessian:
                _hessian_blocks(PA, model, prm, q, ws.X, tabs, n, m, s, J)
            if declared is None:
                for j in range(J + 1):
                    PG |= ws.G[j, :m] != 0.0
    return {"G": PG, "newton": PA}


def _g_pattern_plan(PG):
    """A plan ``si`` that holds G's pattern ``PG`` (m, n) alone, marked so that the residual
    forms ``Gᵀη`` over it (``si[SI_SC]`` not dense, as a structured plan's): for the
    residuals of :func:`detect_pattern`, which solve nothing."""
    gptr, gcol = compressed_rows(PG)
    si = np.zeros(lay.SI_HEADER + len(gptr) + len(gcol), dtype=np.int64)
    si[lay.SI_SC] = lay.SOLVE_BANDED
    si[lay.SI_GPTR] = lay.SI_HEADER
    si[lay.SI_GCOL] = lay.SI_HEADER + len(gptr)
    si[lay.SI_HEADER:] = np.concatenate([gptr, gcol])
    return si


def _constraint_blocks(PA, G, Lc, n, m, s, J):
    """Add to ``PA`` the non-zeros of the Newton matrix's blocks that are ``G`` itself at the
    constraint points, ``∂E_ν/∂η_j = −ℓ_ν(d_j) G_jᵀ`` and ``∂g(q(d_j))/∂ΔQ^μ = ℓ_μ(d_j) G_j``
    (the row and column layout of :func:`fastvi.kernels.step.newton_matrix`). A residual
    moved by a unit of an unknown does not show an entry of G at round-off (an analytic
    zero that a rotation's arithmetic leaves at 1e-18), which the step's assembly writes."""
    sn = s * n
    for j in range(J + 1):
        NZ = G[j, :m] != 0.0
        if j < J:
            for nu in range(s):
                if Lc[nu, j] != 0.0:
                    PA[nu * n:(nu + 1) * n, sn + j * m:sn + (j + 1) * m] |= NZ.T
        if j >= 1:
            for mu in range(1, s + 1):
                if Lc[mu, j] != 0.0:
                    PA[sn + (j - 1) * m:sn + j * m, (mu - 1) * n:mu * n] |= NZ


def _hessian_blocks(PA, model, prm, qk, X, tabs, n, m, s, J):
    """Add to ``PA`` the non-zeros of ``Σ_c η_{j,c} ∇²g_c(q(d_j))`` in the coordinate blocks
    where the step's assembly subtracts it (``ℓ_ν(d_j) ℓ_μ(d_j) ≠ 0``), at the points and
    impulses of the unknowns ``X`` and in the kernel's arithmetic: the model's exact
    Hessian of a rotation's constraints leaves entries at round-off (1e-18) that the
    residual's dependence does not show."""
    sn = s * n
    Lc = tabs.Lc
    for j in range(1, J):
        qd = qk.copy()
        for nu in range(1, s + 1):
            qd += Lc[nu, j] * X[(nu - 1) * n:nu * n]
        NZ = model.callback_value("constraint_hessian", qd, X[sn + j * m:sn + (j + 1) * m],
                                  prm, t=0.01 * tabs.d[j]) != 0.0
        for nu in range(s):
            for mu in range(1, s + 1):
                if Lc[nu, j] * Lc[mu, j] != 0.0:
                    PA[nu * n:(nu + 1) * n, (mu - 1) * n:mu * n] |= NZ


def _ordering(P):
    """RCM permutation of the symmetrised pattern and the bandwidths (kl, ku) after it, of
    the symmetrised pattern too (a margin: the Newton matrices are structurally symmetric
    up to the impulse blocks)."""
    P = P | P.T
    perm = reverse_cuthill_mckee(sp.csr_matrix(P), symmetric_mode=True).astype(np.int64)
    i, j = np.nonzero(P[np.ix_(perm, perm)])
    kl = int(max(0, (i - j).max(initial=0)))
    ku = int(max(0, (j - i).max(initial=0)))
    return perm, kl, ku


def _banded_pays(N, kl, ku, solver, system):
    if solver != "auto":
        return solver in ("banded", "sparse")  # the full Newton matrix needs pivoting
    return N >= BAND_MIN_ROWS[system] and BAND_GAIN * N * (kl + 1) * (kl + ku + 1) < N**3 / 3


_KIND_NAMES = {lay.SOLVE_DENSE: "dense", lay.SOLVE_BANDED: "banded", lay.SOLVE_SPARSE: "sparse"}
_LU_ARRAYS = {lay.LU_DIAG: "diag", lay.LU_LPTR: "lptr", lay.LU_LROW: "lrow", lay.LU_LPOS: "lpos",
              lay.LU_UPTR: "uptr", lay.LU_UCOL: "ucol", lay.LU_UPOS: "upos",
              lay.LU_WPTR: "wptr", lay.LU_WPOS: "wpos"}

_System = namedtuple("_System", ["kind", "band", "perm", "length", "destination", "symbolic",
                                 "costs"])


def _system(P, PS, J, solver, system):
    """Plan one system of the impulses (the projection: ``J = 1``, ``P = PS``; the Schur
    complement: ``P`` the pattern of its ``J × J`` blocks of ``PS``): banded after RCM,
    or sparse LU in the minimum-degree order of the constraints with a constraint's ``J``
    impulses adjacent (static pivots, see :mod:`fastvi.kernels.sparse_lu`), or dense —
    by flop count, the sparse one weighted by ``SPARSE_COST``. ``destination(r, c)`` maps
    entries of the original matrix to their place in the factor storage."""
    N = P.shape[0]
    perm_b, kl, ku = _ordering(P)
    order = minimum_degree(PS)
    perm_s = (np.arange(J)[None, :] * PS.shape[0] + order[:, None]).ravel()
    sym = symbolic_lu(P, perm_s)
    costs = dict(dense=N**3 / 3, banded=BAND_GAIN * N * (kl + 1) * (kl + ku + 1),
                 sparse=SPARSE_COST * sym.flops)
    if solver == "auto":
        kind = min(costs, key=costs.get) if N >= BAND_MIN_ROWS[system] else "dense"
    else:
        kind = solver
    if kind == "banded":
        ip = np.argsort(perm_b)
        ld, kv = band_ld(kl, ku), kl + ku

        def destination(r, c):
            i, col = ip[r], ip[c]
            return ld * col + kv + i - col
        return _System(lay.SOLVE_BANDED, (kl, ku), perm_b, ld * N, destination, None, costs)
    if kind == "sparse":
        ip = np.argsort(perm_s)

        def destination(r, c):
            return np.array([sym.position(i, j) for i, j in zip(ip[r], ip[c])], dtype=np.int64)
        return _System(lay.SOLVE_SPARSE, (kl, ku), perm_s, sym.nnz, destination, sym, costs)
    return _System(lay.SOLVE_DENSE, (kl, ku), perm_b, 0, None, None, costs)


def greedy_colours(neighbours):
    """Greedy colouring in vertex order: vertex ``i`` takes the smallest colour none of
    ``neighbours[i]`` (indices) already has. Returns the colours (int64)."""
    colour = np.full(len(neighbours), -1, dtype=np.int64)
    for i, nb in enumerate(neighbours):
        used = {int(colour[c]) for c in nb if colour[c] >= 0}
        k = 0
        while k in used:
            k += 1
        colour[i] = k
    return colour


def compressed_rows(P):
    """``(ptr, cols)`` of the boolean pattern ``P`` by rows: the columns of row i at
    ``cols[ptr[i] … ptr[i + 1]]``, ascending."""
    P = np.asarray(P, dtype=bool)
    return (np.concatenate(([0], np.cumsum(P.sum(axis=1)))).astype(np.int64),
            np.nonzero(P)[1].astype(np.int64))


def coupling(PG, PA, s: int):
    """The coupling of the coordinates, (n, n) boolean: ``q_a`` and ``q_b`` meet in some
    coordinate block of the Newton matrix of pattern ``PA`` (the mass, the forces and the
    constraint Hessians) or in a constraint of G's pattern ``PG`` (m, n). Every coordinate
    block of the exact Newton matrix, of the step or of the linearised step's extended
    one, is a combination of such terms, so its pattern is within this."""
    PG, PA = np.asarray(PG, dtype=bool), np.asarray(PA, dtype=bool)
    n = PG.shape[1]
    Gs = sp.csr_matrix(PG.astype(np.int64))  # a dense integer product has no BLAS: O(m n²)
    B = (Gs.T @ Gs).toarray() > 0
    for nu in range(s):
        for mu in range(s):
            B |= PA[nu * n:(nu + 1) * n, mu * n:(mu + 1) * n]
    return B


def spans(P):
    """``[lo_0, hi_0, lo_1, hi_1, …]``: row i of the boolean pattern ``P`` is empty outside
    the columns ``lo_i … hi_i − 1`` (``lo = hi = 0``: an empty row)."""
    P = np.asarray(P, dtype=bool)
    out = np.zeros(2 * P.shape[0], dtype=np.int64)
    for i, row in enumerate(P):
        nz = np.flatnonzero(row)
        if nz.size:
            out[2 * i], out[2 * i + 1] = nz[0], nz[-1] + 1
    return out


def linearisation_patterns(PG, PA, s: int, J: int, diagonal_mass: bool = False):
    """What the linearised step of a structured model uses of its patterns (``PG`` of G,
    (m, n), ``PA`` of the step's Newton matrix, (N, N)), for a method of ``s`` and ``J``:
    a dict of int64 arrays for :func:`fastvi.kernels.tangent.make_sparsity`.

    - ``gptr``, ``gcol``: G by rows; ``gsta``, ``grow``: groups of constraints whose
      patterns share no coordinate (a greedy colouring of ``G Gᵀ``; group k's rows at
      ``grow[gsta[k] …]``), empty unless they save at least half of the ``m`` constraint
      Hessians a point would need one by one.
    - ``tptr``, ``tcol``, ``xptr``, ``xcol``: the patterns of ``R_q``, ``P_q`` ((N + n) ×
      n) and ``P_X`` (n × N), from the block structure: every coordinate block of the
      Newton matrix couples ``q_a`` and ``q_b`` through the mass, the forces and the
      constraint Hessians (``B``, the union of its blocks and of ``Gᵀ G``), every impulse
      column through ``Gᵀ``; so ``R_q`` has ``B`` in the rows of the equations and ``G`` in
      the constraint rows, ``P_q`` has ``B``, and ``P_X`` has ``B`` in each position block
      and ``Gᵀ`` in each impulse block (supersets).
    - ``bspan``, ``gspan``: each row's span of non-zeros (:func:`spans`) of ``B``
      symmetrised and of G, for a constant ``diagonal_mass`` only (else empty): ``G M⁻¹``
      then has G's pattern, and ``∂(M v)/∂q`` is zero."""
    PG, PA = np.asarray(PG, dtype=bool), np.asarray(PA, dtype=bool)
    m, n = PG.shape
    z = np.zeros(0, dtype=np.int64)
    out = dict(gptr=z, gcol=z, gsta=z, grow=z)
    Gs = sp.csr_matrix(PG.astype(np.int64))
    if m:
        colour = greedy_colours(((Gs @ Gs.T) > 0).tolil().rows)  # constraints sharing a coordinate
        ng = int(colour.max()) + 1
        if 2 * ng <= m:
            out["gptr"], out["gcol"] = compressed_rows(PG)
            out["grow"] = np.argsort(colour, kind="stable").astype(np.int64)
            out["gsta"] = np.searchsorted(colour[out["grow"]], np.arange(ng + 1)).astype(np.int64)
    B = coupling(PG, PA, s)
    T = np.vstack([B] * s + [PG] * J + [B])
    X = np.hstack([B] * s + [PG.T] * J)
    assert T.shape == (s * n + J * m + n, n) and X.shape == (n, s * n + J * m)
    out["tptr"], out["tcol"] = compressed_rows(T)
    out["xptr"], out["xcol"] = compressed_rows(X)
    if diagonal_mass:
        out["bspan"], out["gspan"] = spans(B | B.T), spans(PG)
    return out


def _column_groups(PG):
    """Curtis–Powell–Reid groups of the columns of the constraint Hessian ``Σ η_i ∇²g_i``,
    whose pattern is that of ``Gᵀ G`` (entry (a, b) only where a constraint involves both):
    columns that share no row go in one group (greedy distance-2 colouring in coordinate
    order). Returns ``(cptr, cols, pptr, rows, bcol)`` — the coordinates of each group and
    the Hessian entries (rows, bcol) each group yields — or None when the groups would not
    save at least half of the ``n`` column-by-column evaluations."""
    Gs = sp.csr_matrix(PG.astype(np.int64))
    H = ((Gs.T @ Gs) > 0).tocsc()
    n = H.shape[0]
    C = ((H.T @ H) > 0).tolil()  # columns that share a row of H
    colour = greedy_colours(C.rows)
    ng = int(colour.max()) + 1 if n else 0
    if 2 * ng > n:
        return None
    cols = np.argsort(colour, kind="stable").astype(np.int64)
    cptr = np.searchsorted(colour[cols], np.arange(ng + 1)).astype(np.int64)
    Hc = H.tocoo()
    order = np.lexsort((Hc.row, Hc.col, colour[Hc.col]))
    rows = Hc.row[order].astype(np.int64)
    bcol = Hc.col[order].astype(np.int64)
    pptr = np.searchsorted(colour[bcol], np.arange(ng + 1)).astype(np.int64)
    return cptr, cols, pptr, rows, bcol


def _constraint_pattern(model, prm, n_states: int = PATTERN_STATES, seed: int = 12):
    """The declared pattern of G, or the union of its non-zeros at ``n_states`` random
    configurations."""
    if model.constraint_jacobian_pattern is not None:
        return model.constraint_jacobian_pattern.copy()
    rng = np.random.default_rng(seed)
    PG = np.zeros((model.m, model.n), dtype=bool)
    for _ in range(n_states):
        PG |= model.constraint_jacobian_value(rng.standard_normal(model.n), prm) != 0.0
    return PG


def plan(model, meth, prm=None, solver: str = "auto") -> Plan:
    """The linear-solve plan of ``model`` with method ``meth`` (memoised on the model per
    method, parameters and ``solver``). ``meth=None``: the projection ``G M⁻¹ Gᵀ`` alone,
    for the RK4 baseline (:mod:`fastvi.baselines.rk4`)."""
    if solver not in SOLVERS:
        raise ValueError(f"`solver` must be one of {', '.join(map(repr, SOLVERS))}, got {solver!r}")
    prm = model.params if prm is None else np.ascontiguousarray(prm, dtype=np.float64)
    cache = _PLANS.setdefault(model, {})
    key = (None if meth is None else meth.name, prm.tobytes(), solver)
    if key in cache:
        return cache[key]
    n, m = model.n, model.m
    s, J = (0, 0) if meth is None else (meth.s, meth.J)
    N = s * n + J * m
    si = np.zeros(lay.SI_HEADER, dtype=np.int64)
    dense = Plan(si, np.zeros(1), dict(newton="dense", schur="dense", projection="dense"),
                 {}, {})
    small = (N < BAND_MIN_ROWS["newton"] and J * m < BAND_MIN_ROWS["schur"]
             and m < BAND_MIN_ROWS["projection"])
    if solver == "dense" or (solver == "auto" and small):  # not even analysed
        cache[key] = dense
        return dense
    pats = dict(G=_constraint_pattern(model, prm)) if meth is None else detect_pattern(model, meth, prm)
    ints = [si]
    off = lay.SI_HEADER
    floats = []
    foff = 0
    solvers, bands = {}, {}

    def put(arr):
        nonlocal off
        ints.append(np.asarray(arr, dtype=np.int64))
        o = off
        off += len(arr)
        return o

    def band(size):
        nonlocal foff
        floats.append(np.zeros(size))
        o = foff
        foff += size
        return o

    perm, kl, ku = _ordering(pats["newton"]) if meth is not None else (None, 0, 0)
    bands["newton"] = (kl, ku)
    if meth is not None and _banded_pays(N, kl, ku, solver, "newton"):
        si[lay.SI_A] = lay.SOLVE_BANDED
        si[lay.SI_A_KL], si[lay.SI_A_KU] = kl, ku
        si[lay.SI_A_PERM] = put(perm)
        si[lay.SI_A_BAND] = band(band_ld(kl, ku) * N)
    solvers["newton"] = "banded" if si[lay.SI_A] else "dense"
    if si[lay.SI_A]:
        PG = pats["G"]
        B = coupling(PG, pats["newton"], s)
        si[lay.SI_BSPAN] = put(spans(B | B.T))
        si[lay.SI_GSPAN] = put(spans(PG))
        if model.force_jacobian_pattern is not None:
            si[lay.SI_FSPAN] = put(spans(model.force_jacobian_pattern))
    flags = model.kernel_arguments()[1]

    def put_g_pattern():
        if not si[lay.SI_GPTR]:
            PG = pats["G"]
            gptr, gcol = compressed_rows(PG)
            si[lay.SI_GPTR] = put(gptr)
            si[lay.SI_GCOL] = put(gcol)

    if m and flags[lay.F_DIAG] and not flags[lay.F_AUGMENT]:  # M⁻¹ elementwise
        PG = pats["G"]
        Gs = sp.csr_matrix(PG.astype(np.int64))
        PS = (Gs @ Gs.T).toarray() > 0
        rows_s, cols_s = np.nonzero(PS)  # row by row: the order of SI_SPTR / SI_SCOL
        proj = _system(PS, PS, 1, solver, "projection")
        bands["projection"] = proj.band
        sysm = [(proj, lay.SI_S, lay.SI_S_KL, lay.SI_S_KU, lay.SI_S_PERM, lay.SI_S_BAND,
                 lay.SI_S_LEN, lay.SI_S_DST, lay.SI_S_LU, [(rows_s, cols_s)])]
        if meth is not None and meth.kernel_tables.mech:
            schur = _system(np.kron(meth.kernel_tables.W != 0.0, PS), PS, J, solver, "schur")
            bands["schur"] = schur.band
            blocks = [((j - 1) * m + rows_s, jp * m + cols_s)
                      for j in range(1, J + 1) for jp in range(J)]
            sysm.append((schur, lay.SI_SC, lay.SI_SC_KL, lay.SI_SC_KU, lay.SI_SC_PERM,
                         lay.SI_SC_BAND, lay.SI_SC_LEN, lay.SI_SC_DST, lay.SI_SC_LU, blocks))
        if any(x[0].kind != lay.SOLVE_DENSE for x in sysm):
            put_g_pattern()
            si[lay.SI_SPTR] = put(np.concatenate(([0], np.cumsum(PS.sum(axis=1)))))
            si[lay.SI_SCOL] = put(cols_s)
        for sy, k_kind, k_kl, k_ku, k_perm, k_store, k_len, k_dst, k_lu, blocks in sysm:
            if sy.kind == lay.SOLVE_DENSE:
                continue
            si[k_kind] = sy.kind
            si[k_kl], si[k_ku] = sy.band
            si[k_perm] = put(sy.perm)
            if k_kind == lay.SI_S:
                si[lay.SI_S_IPERM] = put(np.argsort(sy.perm))
            si[k_len] = sy.length
            si[k_store] = band(sy.length)
            si[k_dst] = put(np.concatenate([sy.destination(r, c) for r, c in blocks]))
            if sy.kind == lay.SOLVE_SPARSE:
                hdr = np.zeros(lay.LU_HEADER, dtype=np.int64)
                si[k_lu] = put(hdr)  # filled in place below: `put` keeps the same array
                for slot, name in _LU_ARRAYS.items():
                    hdr[slot] = put(sy.symbolic.arrays[name])
    if m and meth is not None and not flags[lay.F_EX_CHESS]:
        groups = _column_groups(pats["G"])
        if groups is not None:
            put_g_pattern()
            cptr, cols, pptr, rows, bcol = groups
            si[lay.SI_HC_NG] = len(cptr) - 1
            si[lay.SI_HC_CPTR] = put(cptr)
            si[lay.SI_HC_COLS] = put(cols)
            si[lay.SI_HC_PPTR] = put(pptr)
            si[lay.SI_HC_ROWS] = put(rows)
            si[lay.SI_HC_BCOL] = put(bcol)
    solvers["schur"] = _KIND_NAMES[si[lay.SI_SC]]
    solvers["projection"] = _KIND_NAMES[si[lay.SI_S]]
    si[lay.SI_RHS] = band(max(N, m, 1))
    result = Plan(np.ascontiguousarray(np.concatenate(ints)),
                  np.ascontiguousarray(np.concatenate(floats)), solvers, bands, pats)
    cache[key] = result
    return result


def workspace(model, meth, prm=None, solver: str = "auto", newton: bool = True):
    """:func:`fastvi.kernels.layout.make_workspace` with the plan of :func:`plan` in it
    (``newton=False``: without the full Newton's fields until
    :func:`fastvi.kernels.step.step_kernel` returns stages that take it)."""
    p = plan(model, meth, prm, solver)
    unused = lay.unused_fields(model.kernel_arguments()[1], p.si, newton)
    si, N = p.si, meth.s * model.n + meth.J * model.m
    # a long chain's full Newton assembles into band storage: O(N), not the dense N²
    into_band = lay.assembles_into_band(si, N)
    ws = lay.make_workspace(model.n, model.m, meth.s, meth.r, meth.J,
                            (unused | {"A"}) if into_band else unused)
    if into_band:
        a = int(si[lay.SI_A_PERM])
        si, L = lay.assembly_into_band(si, N, int(si[lay.SI_A_KL]), int(si[lay.SI_A_KU]), si[a: a + N])
        ws = ws._replace(A=np.zeros((0, 0) if "A" in unused else (1, L)))
    if np.any(p.si[:lay.SI_HEADER]):  # something structured: a solve or grouped differences
        ws = ws._replace(si=si.copy(), sb=p.sb.copy(), structured=True)
    return ws


#: with ``specialize=None`` the stages are compiled for a model's sizes when a run takes at
#: least this many steps (an ensemble: member steps) and they are not compiled yet: ≈ 8 s of
#: compiling then saves about as much (0.3–0.8 µs a step of the double pendulum,
#: docs/decisions/0012-sized-stages.md)
SIZED_MIN_STEPS = 10_000_000
#: … and only up to this many coordinates: the sized loops are unrolled, and a large
#: model's step is set by its solves, not by loop overhead
SIZED_MAX_N = 24
#: the linearised step of the derivatives (:func:`fastvi.sensitivity`, :func:`fastvi.adjoint`)
#: is compiled for a model's sizes, with ``specialize=None``, for a run of at least this
#: many steps: its ≈ 40–70 s of compiling save ≈ 1 µs a step of the double pendulum
#: (docs/decisions/0021-sized-linearised-step.md)
SIZED_TANGENT_MIN_STEPS = 100_000_000


def sizing(specialize, n: int, steps: int, min_steps: int = SIZED_MIN_STEPS):
    """What ``step_kernel(sized=…)`` gets for ``specialize`` (``None``: automatic), a model
    of ``n`` coordinates and a run of ``steps`` steps: ``True`` (compile the sized stages),
    ``"cached"`` (use them if compiled already) or ``False``; ``min_steps``: the run that
    repays their compile (:data:`SIZED_TANGENT_MIN_STEPS` for the linearised step)."""
    if specialize is not None:
        return bool(specialize)
    if n > SIZED_MAX_N:
        return False
    return True if steps >= min_steps else "cached"
