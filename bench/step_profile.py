"""Where a step's time goes: each part of the step kernel timed in its own compiled loop.

``python -m bench.step_profile [METHOD …]`` (from the repository root) prints, for the double
pendulum, the CPU time per call of the whole step (both Newton variants) and of its parts —
the residual, the residual with the full Newton matrix, the dense LU and solve of that matrix,
the mechanics-matrix solve, the end projection, one model callback — together with the calls
per step, so that the parts can be added up and compared with the step (``docs/benchmarks.md``,
"The step"); ``bench/test_bench_step_parts.py`` runs it under ``make bench``.

The profile calls the kernels one by one, so it reads fastvi's internals (``fastvi.kernels``):
it is a developer's measurement, kept beside the benchmarks, not a part of the package.
"""

from __future__ import annotations

import sys
import time

import numpy as np

import fastvi
from fastvi._numba import hot, ptr, quiet
from fastvi.kernels import layout as lay
from fastvi.kernels.layout import make_workspace
from fastvi.kernels.linalg import lu_factor, lu_solve
from fastvi.kernels.step import (_exact_mechanics, _mech_solve, assemble, end_momentum, residual,
                                 step_kernel, step_once, take_step)

#: compiled loops that inline fastvi's kernels: cached under the package's stamp and this file's
#: (``fastvi._numba.STAMP_OPT_IN``), so that an edited kernel recompiles them
FASTVI_CACHE_STAMP = True

__all__ = ["profile_step", "main", "loop_step", "loop_residual", "loop_assemble", "loop_lu",
           "loop_solve", "loop_mech", "loop_end", "loop_callback"]


# The loops are compiled like the kernels they time (``hot``: no reference counting, so
# the caller passes every scratch array): a loop that counts references to the views it
# takes times numba's atomic counts, not the kernel (a sized residual measured 0.76 µs in
# such a loop against 0.066 µs in a ``hot`` one;
# docs/decisions/0006-kernels-without-reference-counting.md).
@hot
def loop_step(md, tabs, opts, h, state, ws, out, stepk, stages, K):
    """``K`` steps from ``state``, each continuing from the last (``out``: the step's output),
    through the compiled step ``stepk`` and its ``stages`` (:func:`.step.step_kernel`)."""
    st = 0
    for _ in range(K):
        st += take_step(md, tabs, opts, h, state, ws, False, out, stepk, stages)
        for a in range(state.shape[1]):
            state[0, a] = state[3, a]
            state[1, a] = state[4, a]
            state[2, a] = state[5, a]
    return st


@hot
def loop_residual(md, tabs, h, qk, pk, ws, K):
    """``K`` residuals of the mechanics iteration at ``ws.X``."""
    st = 0
    for _ in range(K):
        st += residual(md, tabs, h, qk, pk, ws)
    return st


@hot
def loop_assemble(md, tabs, h, qk, pk, ws, jac, K):
    """``K`` assemblies of the full Newton's residual (with its matrix when ``jac``)."""
    st = 0
    for _ in range(K):
        st += assemble(md, tabs, h, qk, pk, ws, jac)
    return st


@hot
def loop_lu(A0, A, piv, N, factor, K):
    """``K`` copies of ``A0`` into ``A``, each factored when ``factor`` (without: the copy's
    own cost, to subtract)."""
    st = 0
    for _ in range(K):
        for i in range(N):
            for j in range(N):
                A[i, j] = A0[i, j]
        if factor:
            st += lu_factor(A, piv, N)
    return st


@hot
def loop_solve(A, piv, R0, R, N, K):
    """``K`` solves with the LU factors in ``A`` of a copy of ``R0``."""
    for _ in range(K):
        for i in range(N):
            R[i] = R0[i]
        lu_solve(A, piv, R, N)
    return 0


@hot
def loop_mech(md, tabs, h, ws, R0, n, m, s, J, K):
    """``K`` mechanics-matrix solves of a copy of ``R0``."""
    st = 0
    N = R0.shape[0]
    # the Schur complement as the step left it: inverted, or factored where the iteration
    # is Newton's method (s = 1, nothing dropped) and rebuilds it at every iteration
    inverse = not (s == 1 and _exact_mechanics(md))
    for _ in range(K):
        for i in range(N):
            ws.R[i] = R0[i]
        st += _mech_solve(md, tabs, h, ws, n, m, s, J, inverse)
    return st


@hot
def loop_end(md, q1, P, p1, v1, G1, ws, out, K):
    """``K`` end projections (RATTLE's momentum at the step end)."""
    st = 0
    for _ in range(K):
        st += end_momentum(md, q1, P, p1, v1, G1, ws, out)
    return st


@hot
def loop_callback(fn, q, prm, out, K):
    """``K`` calls of one model callback."""
    acc = 0.0
    for _ in range(K):
        fn(ptr(q), ptr(q), ptr(prm), ptr(out))
        acc += out[0]
    return acc


def _per_call(fn, *args, calls=20000, repeats=5):
    """Best-of-``repeats`` thread CPU time per call of a compiled loop of ``calls`` calls."""
    fn(*args, 10)
    best = np.inf
    for _ in range(repeats):
        t0 = time.thread_time()
        fn(*args, calls)
        best = min(best, (time.thread_time() - t0) / calls)
    return best


def profile_step(model, q0, v0, method: str = "P2L-Q3G", h: float = 0.01, warm: int = 2000,
                 calls: int = 20000) -> dict:
    """CPU seconds per call of the step and of its parts, at a state ``warm`` steps in.

    Returns a dict with ``step_auto``, ``step_full`` (one step, each Newton variant),
    ``residual``, ``residual_jacobian``, ``lu_factor``, ``lu_solve``, ``mech_solve``,
    ``end_momentum``, ``callback`` (one ∇V call) and ``iterations_auto``,
    ``iterations_full`` (Newton iterations per step) and ``N`` (unknowns per step).
    """
    meth = fastvi.method(method)
    prm = model.kernel_params()
    md = model.kernel_data()
    tabs = meth.kernel_tables
    n, m, s, J = model.n, model.m, meth.s, meth.J
    N = s * n + J * m
    out: dict[str, float] = dict(N=N)
    with quiet():
        for mode in ("auto", "full"):
            res = fastvi.integrate(model, q0, v0, h=h, n_steps=warm, method=method, newton=mode,
                                   save_every=warm)
            out[f"iterations_{mode}"] = res.stats["newton_iterations"] / warm
            state = np.zeros((6, n))
            state[0], state[1], state[2] = res.q[-1], res.p[-1], res.v[-1]
            ws = make_workspace(n, m, s, meth.r, J)
            opts = lay.NewtonOptions(1e-14, 30, lay.NEWTON_MODES[mode])
            # a first step fills the predictor's history; the loop then runs on
            st0 = np.zeros(lay.STEP_OUT_SIZE)
            step_once(md, tabs, opts, h, state, ws, True, st0)
            out[f"step_{mode}"] = _per_call(loop_step, md, tabs, opts, h, state, ws, st0,
                                            *step_kernel(md, tabs, opts, ws, full=True),
                                            calls=calls)
        qk, pk = state[0].copy(), state[1].copy()
        ws = make_workspace(n, m, s, meth.r, J)
        step_once(md, tabs, lay.NewtonOptions(1e-14, 30, lay.NEWTON_FULL), h, state, ws, True,
                  np.zeros(lay.STEP_OUT_SIZE))
        out["residual"] = _per_call(loop_residual, md, tabs, h, qk, pk, ws, calls=calls)
        out["residual_generic"] = _per_call(loop_assemble, md, tabs, h, qk, pk, ws, False,
                                            calls=calls)
        out["residual_jacobian"] = _per_call(loop_assemble, md, tabs, h, qk, pk, ws, True,
                                             calls=calls)
        A0 = ws.A.copy()
        R0 = ws.R.copy()
        A, piv, R = np.zeros((N, N)), np.zeros(N, dtype=np.int64), np.zeros(N)
        out["lu_factor"] = (_per_call(loop_lu, A0, A, piv, N, True, calls=calls)
                            - _per_call(loop_lu, A0, A, piv, N, False, calls=calls))
        out["lu_solve"] = _per_call(loop_solve, A, piv, R0, R, N, calls=calls)
        # the mechanics solve needs M̄⁻¹ and Y_0 prepared as a step does
        ws2 = make_workspace(n, m, s, meth.r, J)
        step_once(md, tabs, lay.NewtonOptions(1e-14, 30, lay.NEWTON_AUTO), h, state, ws2, True,
                  np.zeros(lay.STEP_OUT_SIZE))
        out["mech_solve"] = _per_call(loop_mech, md, tabs, h, ws2, ws2.R.copy(), n, m, s, J,
                                      calls=calls)
        q1, P = state[3].copy(), ws.P.copy()
        p1, v1 = np.zeros(n), np.zeros(n)
        out["end_momentum"] = _per_call(loop_end, md, q1, P, p1, v1, ws.G[J].copy(), ws,
                                        np.zeros(lay.STEP_OUT_SIZE), calls=calls)
        out["callback"] = _per_call(loop_callback, md.fns[lay.PGRAD], qk, prm, np.zeros(n),
                                    calls=calls)
    return out


def main(argv=None) -> None:
    methods = (argv or sys.argv[1:]) or ["P1L-Q2G", "P2L-Q3G", "P3L-Q4G"]
    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(np.pi / 2, np.pi / 2)
    for meth in methods:
        p = profile_step(model, q0, v0, meth)
        us = {k: v * 1e6 for k, v in p.items() if k not in ("N",) and not k.startswith("iter")}
        print(f"{meth} (N = {p['N']}): iterations/step auto {p['iterations_auto']:.2f}, "
              f"full {p['iterations_full']:.2f}")
        for k, v in us.items():
            print(f"  {k:18s} {v:8.3f} µs")


if __name__ == "__main__":
    main()
