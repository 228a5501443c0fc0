"""Where a size-specialized step's time goes: each part timed in its own compiled loop.

    .venv/bin/python bench/step_parts.py [METHOD ...]     (default P3L-Q4G)

``fastvi.studies.profile`` times the parts of the generic kernels; this does the same for
the kernels of ``integrate(..., specialize=True)`` on the double pendulum (h = 0.01, a state
2000 steps in): the sized step (called, not inlined into a time loop), and the parts of the
mechanics iteration — the residual and the mechanics solve (each once per iteration), the
Schur complement built and inverted, the predictor, the end of the iteration and the end
projection (each once per step) — and the Gauss–Jordan inverse alone. The loops are compiled
without reference counting, as the kernels are (``fastvi._numba.hot``); a loop with it
measures numba's reference counts, not the kernel. Best of 7 runs of 50 000 calls, thread
CPU time, in µs per call (``docs/benchmarks.md``). Compiles every loop afresh (minutes).
"""

import sys
import time

import numba as nb
import numpy as np

import fastvi
from fastvi._numba import _OPTIONS
from fastvi.kernels import layout as lay
from fastvi.kernels import step as S
from fastvi.kernels.layout import make_workspace, specialize
from fastvi.kernels.linalg import invert_unpivoted

#: the kernels' own options, without the disk cache
hot = nb.njit(**{**_OPTIONS, "cache": False}, _nrt=False)
H = 0.01


@hot
def _steps(md, tabs, opts, h, state, ws, out, K):
    for _ in range(K):
        S.step(md, tabs, opts, h, state, ws, False, out)
        for a in range(state.shape[1]):
            state[0, a] = state[3, a]
            state[1, a] = state[4, a]
            state[2, a] = state[5, a]
    return 0


@hot
def _residuals(md, tabs, h, qk, pk, ws, K):
    st = 0
    for _ in range(K):
        st += S.residual(md, tabs, h, qk, pk, ws)
    return st


@hot
def _mech_solves(md, tabs, h, ws, R0, K):
    n, m, s, _, J = lay.sizes(ws)
    for _ in range(K):
        for i in range(R0.shape[0]):
            ws.R[i] = R0[i]
        S._mech_solve(md, tabs, h, ws, n, m, s, J, True)
    return 0


@hot
def _schurs(md, tabs, h, ws, K):
    n, m, s, _, J = lay.sizes(ws)
    st = 0
    for _ in range(K):
        for j in range(1, J):
            S._mech_rows(md, ws, j, n, m)
        st += S._schur(tabs, h, ws, n, m, J, True)
    return st


@hot
def _inverses(ws, S0, K):
    _, m, _, _, J = lay.sizes(ws)
    st = 0
    for _ in range(K):
        for i in range(J * m):
            for k in range(J * m):
                ws.Sc[i, k] = S0[i, k]
        st += invert_unpivoted(ws.Sc, J * m)
    return st


@hot
def _predicts(tabs, h, vk, ws, K):
    n, m, _, _, _ = lay.sizes(ws)
    for _ in range(K):
        S.predict(tabs, n, m, h, vk, ws, 2)
    return 0


@hot
def _finishes(md, tabs, h, qk, ws, q1, K):
    n, m, s, _, J = lay.sizes(ws)
    g = 0.0
    for _ in range(K):
        g += S._finish_mech(md, tabs, h, qk, ws, q1, n, m, s, J)
    return g


@hot
def _ends(md, q1, P, p1, v1, G1, ws, out, K):
    st = 0
    for _ in range(K):
        st += S.end_momentum(md, q1, P, p1, v1, G1, ws, out)
    return st


def _per_call(fn, *args, calls=50_000):
    fn(*args, 10)
    best = np.inf
    for _ in range(7):
        t0 = time.thread_time()
        fn(*args, calls)
        best = min(best, (time.thread_time() - t0) / calls)
    return 1e6 * best


def parts(method):
    model = fastvi.scenes.double_pendulum()
    q0, v0 = model.initial_state(np.pi / 2, np.pi / 2)
    meth = fastvi.method(method)
    md, tabs = model.kernel_data(), meth.kernel_tables
    n, m, s, J = model.n, model.m, meth.s, meth.J
    res = fastvi.integrate(model, q0, v0, h=H, n_steps=2000, method=method, save_every=2000)
    state = np.zeros((6, n))
    state[0], state[1], state[2] = res.q[-1], res.p[-1], res.v[-1]
    ws = specialize(make_workspace(n, m, s, meth.r, J))
    opts = lay.NewtonOptions(1e-14, 30, lay.NEWTON_AUTO)
    out = np.zeros(lay.STEP_OUT_SIZE)
    S.step(md, tabs, opts, H, state, ws, True, out)
    for _ in range(3):  # fill the predictor's history
        S.step(md, tabs, opts, H, state, ws, False, out)
        state[:3] = state[3:]
    times = {"step (called)": _per_call(_steps, md, tabs, opts, H, state, ws, out)}
    S.step(md, tabs, opts, H, state, ws, False, out)
    iters = out[lay.S_ITERS]
    qk, pk = state[0].copy(), state[1].copy()
    times["residual"] = _per_call(_residuals, md, tabs, H, qk, pk, ws)
    times["mechanics solve"] = _per_call(_mech_solves, md, tabs, H, ws, ws.R.copy())
    times["Schur build + inverse"] = _per_call(_schurs, md, tabs, H, ws)
    S0 = np.random.default_rng(0).normal(size=ws.Sc.shape)
    times["inverse alone (+ copy)"] = _per_call(_inverses, ws, S0)
    times["predictor"] = _per_call(_predicts, tabs, H, state[2].copy(), ws)
    times["end of the iteration"] = _per_call(_finishes, md, tabs, H, qk, ws, np.zeros(n))
    times["end projection"] = _per_call(_ends, md, state[3].copy(), ws.P.copy(), np.zeros(n),
                                        np.zeros(n), ws.G[J].copy(), ws, out)
    return iters, times


def main(methods):
    for method in methods or ["P3L-Q4G"]:
        iters, times = parts(method)
        print(f"{method} (sized; the timed state's step took {iters:.0f} iterations)")
        for name, us in times.items():
            print(f"  {name:24s} {us:7.4f} µs")


if __name__ == "__main__":
    main(sys.argv[1:])
