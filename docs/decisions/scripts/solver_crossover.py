"""Crossover of the linear solvers of a step (issue 12): dense, banded and sparse LU side by
side, on a chain (banded pattern) and on trees (a hub joining many branches: no narrow band).

For each scene and size, one ``integrate`` call per solver forced with ``solver=`` (the
Schur complement of the mechanics iteration and the end projection; the full Newton matrix,
used only when the mechanics iteration falls back, stays banded for "banded" and "sparse"),
interleaved in rounds so that the machine's load hits every solver alike; the median of
the integration loop's time per step (``stats["integration_time"]``), the flop counts the
automatic choice compares (:func:`fastvi.structure._system`) and what ``"auto"`` picks.
The trajectories of the solvers are compared too (they agree at round-off).

    .venv/bin/python docs/decisions/scripts/solver_crossover.py [rounds] [--scenes=chain,ladder,tree]
"""

from __future__ import annotations

import sys

import time

import numpy as np
from numba import njit

import fastvi
from fastvi import structure
from fastvi.kernels import layout as lay
from fastvi.kernels.banded import band_factor, band_solve
from fastvi.kernels.sparse_lu import sparse_factor, sparse_solve

METHOD = "P2L-Q3G"
H = 0.01
BUDGET = 20_000  # steps of a run ≈ BUDGET / bodies
DENSE_UP_TO = 96  # constraints: beyond, the dense path takes seconds a run


def scenes(which):
    if "chain" in which:
        for N in (16, 32, 64, 128, 256):
            mod = fastvi.scenes.chain(N)
            yield f"chain({N})", mod, mod.initial_state(np.linspace(0.2, 1.0, N))
    if "ladder" in which:
        for N in (8, 16, 32, 64):
            mod = fastvi.scenes.ladder(N)
            yield f"ladder({N})", mod, mod.initial_state(np.full(N, 0.3))
    if "tree" in which:
        for b, L in ((4, 4), (8, 4), (8, 8), (16, 8), (32, 4), (16, 16)):
            mod = fastvi.scenes.tree(b, L)
            N = 1 + b * L
            th = 0.3 + 0.6 * np.sin(np.arange(N))
            yield f"tree({b},{L})", mod, mod.initial_state(th)


@njit(cache=False)
def _factor_loop(kind, si, st0, st, piv, t, lu, N, kl, ku, reps):
    for _ in range(reps):
        st[:] = st0
        if kind == 1:
            band_factor(st, piv, N, kl, ku)
            band_solve(st, piv, t, N, kl, ku)
        else:
            sparse_factor(si, st, lu, N)
            sparse_solve(si, st, lu, t, N)


def kernel_times(mod, meth, reps=2000):
    """µs of one factorisation + solve of the Schur complement, banded and sparse, on a
    matrix with its pattern (values: a random diagonally dominant matrix), in a compiled
    loop; the copy of the factor storage that stands for the assembly is included."""
    out = {}
    rng = np.random.default_rng(1)
    for solver in ("banded", "sparse"):
        p = structure.plan(mod, meth, solver=solver)
        si, m, J = p.si, mod.m, meth.J
        Jm = J * m
        Gi = p.patterns["G"].astype(np.int64)
        PS = (Gi @ Gi.T) > 0
        P = np.kron(meth.kernel_tables.W != 0, PS)
        A = np.where(P, rng.standard_normal(P.shape), 0.0) + 4.0 * J * np.eye(Jm)
        st0 = np.zeros(si[lay.SI_SC_LEN])
        rows, cols = np.nonzero(PS)
        nnz = len(rows)
        for j in range(J):
            for jp in range(J):
                d = si[si[lay.SI_SC_DST] + (j * J + jp) * nnz: si[lay.SI_SC_DST] + (j * J + jp + 1) * nnz]
                st0[d] = A[j * m + rows, jp * m + cols]
        st = st0.copy()
        t = rng.standard_normal(Jm)
        piv = np.zeros(Jm, dtype=np.int64)
        args = (si[lay.SI_SC], si, st0, st, piv, t, si[lay.SI_SC_LU], Jm, si[lay.SI_SC_KL],
                si[lay.SI_SC_KU])
        _factor_loop(*args, 2)
        best = []
        for _ in range(5):
            t0 = time.perf_counter()
            _factor_loop(*args, reps)
            best.append((time.perf_counter() - t0) / reps)
        out[solver] = 1e6 * float(np.median(best))
    return out


def main(argv):
    rounds = int(argv[0]) if argv and argv[0].isdigit() else 3
    which = next((a.split("=", 1)[1] for a in argv if a.startswith("--scenes=")), "chain,ladder,tree")
    meth = fastvi.method(METHOD)
    print(f"{'scene':>12} {'m':>4} {'auto':>7} {'flops b/s':>15} {'dense':>9} {'banded':>9} "
          f"{'sparse':>9} {'b/s':>6} {'max|dq|':>8} {'LU b us':>8} {'LU s us':>8}")
    for name, mod, (q0, v0) in scenes(which):
        steps = max(20, BUDGET // mod.m)
        solvers = ["banded", "sparse"] + (["dense"] if mod.m <= DENSE_UP_TO else [])
        times = {s: [] for s in solvers}
        qs = {}
        for s in solvers:  # compile, check, plan
            fastvi.integrate(mod, q0, v0, h=H, n_steps=2, method=METHOD, solver=s)
        for _ in range(rounds):
            for s in solvers:
                r = fastvi.integrate(mod, q0, v0, h=H, n_steps=steps, method=METHOD, solver=s,
                                     save_every=steps)
                times[s].append(r.stats["integration_time"] / steps)
                qs[s] = r.q[-1]
        med = {s: 1e6 * float(np.median(t)) for s, t in times.items()}
        auto = structure.plan(mod, meth, solver="auto").solvers["schur"]
        sy = structure._system
        Gi = structure.detect_pattern(mod, meth)["G"].astype(np.int64)
        PS = (Gi @ Gi.T) > 0
        c = sy(np.kron(meth.kernel_tables.W != 0, PS), PS, meth.J, "auto", "schur").costs
        k = kernel_times(mod, meth)
        dq = max(np.abs(qs[s] - qs["banded"]).max() for s in solvers)
        dense = f"{med['dense']:9.1f}" if "dense" in med else f"{'-':>9}"
        print(f"{name:>12} {mod.m:>4} {auto:>7} {int(c['banded']):>7}/{int(c['sparse'] / structure.SPARSE_COST):<7} "
              f"{dense} {med['banded']:9.1f} {med['sparse']:9.1f} "
              f"{med['banded'] / med['sparse']:6.2f} {dq:8.1e} {k['banded']:8.2f} {k['sparse']:8.2f}",
              flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
