r"""Sparsity of a model and the plan of a step's linear solves (issue 12).

Once per model, method and parameter vector, in NumPy:

1. **The pattern.** The non-zeros of ``G`` and of the full Newton matrix are detected by
   evaluating the model at ``PATTERN_STATES`` random states (configurations, velocities,
   impulses and unknowns drawn from a normal distribution, not consistent ones: a
   structural zero does not depend on the state) and taking the union. The Newton matrix
   is assembled by the step kernel itself, so the pattern holds exactly what the kernel
   writes, finite-difference Hessians included (a coordinate on which a derivative does not
   depend gives an exact zero difference). A zero that is only accidental at one random
   state is caught by the other states (probability zero otherwise). A model may declare
   the pattern of ``G`` instead (``Model(constraint_jacobian_pattern=)``, verified by
   :meth:`fastvi.Model.check`); its callback then writes only those entries. From ``G``: the
   patterns of ``G Gᵀ`` (the projection) and of the Schur complement of the mechanics
   iteration.
2. **The ordering.** SciPy's reverse Cuthill–McKee on each symmetrised pattern, and the
   lower/upper bandwidths of the permuted matrix.
3. **The choice.** Banded LU (:mod:`fastvi.kernels.banded`) where it is cheaper than the
   dense LU by the measured crossover (``BAND_MIN_ROWS``, ``BAND_GAIN``), the dense LU
   otherwise — every small model keeps the dense path, bit for bit, and is not even
   analysed. The Schur complement and the projection use the pattern
   of ``G`` only with a diagonal constant mass (``M⁻¹`` is otherwise dense).

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

from collections import namedtuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import reverse_cuthill_mckee

from ._numba import quiet
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
#: the ``solver`` choices: automatic, or forced for every system (for tests and benchmarks)
SOLVERS = ("auto", "dense", "banded")

Plan = namedtuple("Plan", ["si", "sb", "solvers", "bandwidths", "patterns"])
Plan.__doc__ = """A step's linear-solve plan: the workspace arrays ``si``, ``sb`` and, for
people, ``solvers`` / ``bandwidths`` ({"newton", "schur", "projection"} → "dense"/"banded",
(kl, ku)) and the detected ``patterns`` ({"G", "newton"} → boolean arrays)."""

_PLANS_ATTR = "_structure_plans"


def detect_pattern(model, meth, prm=None, n_states: int = PATTERN_STATES, seed: int = 12):
    """Boolean non-zero patterns ``{"G": (m, n), "newton": (N, N)}``, the union over
    ``n_states`` random states (see the module docstring); ``G``'s is the model's
    ``constraint_jacobian_pattern`` where it declares one."""
    from .kernels.step import assemble

    prm = model.params if prm is None else np.ascontiguousarray(prm, dtype=np.float64)
    rng = np.random.default_rng(seed)
    n, m, s, J = model.n, model.m, meth.s, meth.J
    N = s * n + J * m
    md = model.kernel_data(prm)
    ws = lay.make_workspace(n, m, s, meth.r, J)
    PG = np.zeros((m, n), dtype=bool)
    PA = np.zeros((N, N), dtype=bool)
    declared = model.constraint_jacobian_pattern  # checked by Model.check, taken as it is
    tabs = meth.kernel_tables
    for _ in range(n_states):
        q = rng.standard_normal(n)
        if m:
            G0 = model.constraint_jacobian_value(q, prm)
            PG |= G0 != 0.0 if declared is None else declared
            ws.G[0, :m] = G0  # G at q_k: the step kernel sets it before Newton
        ws.X[:] = 0.1 * rng.standard_normal(N)
        with quiet():
            assemble(md, tabs, 0.01, q, rng.standard_normal(n), ws, True)
        PA |= ws.A[:N, :N] != 0.0
        if m and declared is None:
            for j in range(J + 1):
                PG |= ws.G[j, :m] != 0.0
    return {"G": PG, "newton": PA}


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
        return solver == "banded"
    return N >= BAND_MIN_ROWS[system] and BAND_GAIN * N * (kl + 1) * (kl + ku + 1) < N**3 / 3


def plan(model, meth, prm=None, solver: str = "auto") -> Plan:
    """The linear-solve plan of ``model`` with method ``meth`` (memoised on the model per
    method, parameters and ``solver``)."""
    if solver not in SOLVERS:
        raise ValueError(f"`solver` must be one of {', '.join(map(repr, SOLVERS))}, got {solver!r}")
    prm = model.params if prm is None else np.ascontiguousarray(prm, dtype=np.float64)
    cache = model.__dict__.setdefault(_PLANS_ATTR, {})
    key = (meth.name, prm.tobytes(), solver)
    if key in cache:
        return cache[key]
    n, m, s, J = model.n, model.m, meth.s, meth.J
    N = s * n + J * m
    si = np.zeros(lay.SI_HEADER, dtype=np.int64)
    dense = Plan(si, np.zeros(1), dict(newton="dense", schur="dense", projection="dense"),
                 {}, {})
    small = (N < BAND_MIN_ROWS["newton"] and J * m < BAND_MIN_ROWS["schur"]
             and m < BAND_MIN_ROWS["projection"])
    if solver == "dense" or (solver == "auto" and small):  # not even analysed
        cache[key] = dense
        return dense
    pats = detect_pattern(model, meth, prm)
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

    perm, kl, ku = _ordering(pats["newton"])
    bands["newton"] = (kl, ku)
    if _banded_pays(N, kl, ku, solver, "newton"):
        si[lay.SI_A] = lay.SOLVE_BANDED
        si[lay.SI_A_KL], si[lay.SI_A_KU] = kl, ku
        si[lay.SI_A_PERM] = put(perm)
        si[lay.SI_A_BAND] = band(band_ld(kl, ku) * N)
    solvers["newton"] = "banded" if si[lay.SI_A] else "dense"
    flags = model.kernel_arguments()[1]
    if m and flags[lay.F_DIAG]:
        PG = pats["G"]
        Gi = PG.astype(np.int64)
        PS = (Gi @ Gi.T) > 0
        W = meth.kernel_tables.W
        PSc = np.zeros((J * m, J * m), dtype=bool)
        for j in range(1, J + 1):
            for jp in range(J):
                if W[j - 1, jp] != 0.0:
                    PSc[(j - 1) * m:j * m, jp * m:(jp + 1) * m] |= PS
        rows, cols = np.nonzero(PG)
        gptr = np.concatenate(([0], np.cumsum(PG.sum(axis=1))))
        rows_s, cols_s = np.nonzero(PS)
        sptr = np.concatenate(([0], np.cumsum(PS.sum(axis=1))))
        p_s, kl_s, ku_s = _ordering(PS)
        p_sc, kl_sc, ku_sc = _ordering(PSc)
        bands["projection"] = (kl_s, ku_s)
        bands["schur"] = (kl_sc, ku_sc)
        use_s = _banded_pays(m, kl_s, ku_s, solver, "projection")
        use_sc = meth.kernel_tables.mech and _banded_pays(J * m, kl_sc, ku_sc, solver, "schur")
        if use_s or use_sc:
            si[lay.SI_GPTR] = put(gptr)
            si[lay.SI_GCOL] = put(cols)
            si[lay.SI_SPTR] = put(sptr)
            si[lay.SI_SCOL] = put(cols_s)
        if use_s:
            si[lay.SI_S] = lay.SOLVE_BANDED
            si[lay.SI_S_KL], si[lay.SI_S_KU] = kl_s, ku_s
            si[lay.SI_S_PERM] = put(p_s)
            si[lay.SI_S_IPERM] = put(np.argsort(p_s))
            si[lay.SI_S_BAND] = band(band_ld(kl_s, ku_s) * m)
        if use_sc:
            si[lay.SI_SC] = lay.SOLVE_BANDED
            si[lay.SI_SC_KL], si[lay.SI_SC_KU] = kl_sc, ku_sc
            si[lay.SI_SC_PERM] = put(p_sc)
            si[lay.SI_SC_IPERM] = put(np.argsort(p_sc))
            si[lay.SI_SC_BAND] = band(band_ld(kl_sc, ku_sc) * J * m)
    solvers["schur"] = "banded" if si[lay.SI_SC] else "dense"
    solvers["projection"] = "banded" if si[lay.SI_S] else "dense"
    si[lay.SI_RHS] = band(max(N, 1))
    result = Plan(np.ascontiguousarray(np.concatenate(ints)),
                  np.ascontiguousarray(np.concatenate(floats)), solvers, bands, pats)
    cache[key] = result
    return result


def workspace(model, meth, prm=None, solver: str = "auto"):
    """:func:`fastvi.kernels.layout.make_workspace` with the plan of :func:`plan` in it."""
    p = plan(model, meth, prm, solver)
    ws = lay.make_workspace(model.n, model.m, meth.s, meth.r, meth.J)
    if p.solvers and any(v == "banded" for v in p.solvers.values()):
        ws = ws._replace(si=p.si.copy(), sb=p.sb.copy())
    return ws
