"""The time loops: the only place that iterates over steps.

``run`` advances one trajectory by a chunk of steps (the Python driver calls it once, or in
chunks when it shows progress; the state carries everything, so chunking changes no bit).
"""

import numpy as np

from .._numba import njit, ptr
from .step import _POT, step

# layout of the float64 ``info`` vector shared with fastvi.integrate
I_STEPS, I_ITERS, I_WIN_G, I_WIN_GV, I_WIN_IT, I_RES, I_FAILED, I_SLOT, I_FIRST, I_MAXRES = range(10)
INFO_SIZE = 10


@njit
def energy(fns, prm, q, p, v, scratch):
    """H = ½ vᵀp + V(q) with v = M⁻¹p already known."""
    fns[_POT](ptr(q), ptr(q), ptr(prm), ptr(scratch))
    e = scratch[0]
    for a in range(q.shape[0]):
        e += 0.5 * v[a] * p[a]
    return e


@njit
def accept(fns, prm, h, state, ws, n_total, save_every, outs, info, iters, gmax, gvmax, res):
    """Book-keeping after a step has been taken (state rows 0–2 already hold the new state):
    counters, residual windows, and the sample when one is due."""
    T, Qs, Vs, Ps, En, Gr, GVr, It = outs
    q, p, v = state[0], state[1], state[2]
    info[I_MAXRES] = max(info[I_MAXRES], res)
    info[I_WIN_G] = max(info[I_WIN_G], gmax)
    info[I_WIN_GV] = max(info[I_WIN_GV], gvmax)
    info[I_WIN_IT] += iters
    k = int(info[I_STEPS]) + 1
    info[I_STEPS] = k
    if k % save_every == 0 or k == n_total:
        j = int(info[I_SLOT])
        T[j] = k * h
        for a in range(q.shape[0]):
            Qs[j, a] = q[a]
            Vs[j, a] = v[a]
            Ps[j, a] = p[a]
        En[j] = energy(fns, prm, q, p, v, ws[9][0])
        Gr[j] = info[I_WIN_G]
        GVr[j] = info[I_WIN_GV]
        It[j] = info[I_WIN_IT]
        info[I_WIN_G] = 0.0
        info[I_WIN_GV] = 0.0
        info[I_WIN_IT] = 0.0
        info[I_SLOT] = j + 1


@njit
def run(fns, flags, Mc, prm, tabs, h, tol, max_iter, state, ws, n_chunk, n_total, save_every, outs, info):
    """Advance ``state`` (rows q, p, v, then scratch) by up to ``n_chunk`` steps.

    Saves every ``save_every``-th step and the last one into ``outs`` =
    (t, q, v, p, energy, max|g|, max|Gv|, Newton iterations), the residuals and iterations
    being the maxima/sums over the steps since the previous sample. Returns a status code;
    on failure ``info[I_FAILED]`` holds the index of the step that failed.
    """
    q, p, v, q1, p1, v1 = state[0], state[1], state[2], state[3], state[4], state[5]
    sout = np.zeros(4)  # once per chunk, not per step
    n = q.shape[0]
    for _ in range(n_chunk):
        k = int(info[I_STEPS])
        if k >= n_total:
            break
        status = step(fns, flags, Mc, prm, tabs, h, q, p, v, q1, p1, v1, ws, tol, max_iter,
                      info[I_FIRST] != 0.0, sout)
        info[I_ITERS] += sout[0]
        info[I_RES] = sout[3]
        if status != 0:
            info[I_FAILED] = k
            return status
        info[I_FIRST] = 0.0
        for a in range(n):
            q[a] = q1[a]
            p[a] = p1[a]
            v[a] = v1[a]
        accept(fns, prm, h, state, ws, n_total, save_every, outs, info, sout[0], sout[1], sout[2], sout[3])
    return 0


# ----------------------------------------------------------------------------- ensembles
# The prange driver: one workspace and one state per member, the same ``step`` in the same
# order as ``run``, so member i of an ensemble equals ``fastvi.integrate`` of member i bit
# for bit. A failing member stops only itself.
from numba import prange  # noqa: E402  (kept beside the ensemble kernels it serves)

from .step import make_workspace  # noqa: E402

#: save modes of ``run_ensemble``
SAVE_FINAL, SAVE_STRIDE, SAVE_DIAGNOSTICS = 0, 1, 2
# columns of the per-member int64 rows ``ist``
E_STATUS, E_STEPS, E_FAILED, E_SAVED = range(4)
E_SIZE = 4
# columns of the per-member float64 rows ``fst``: Newton iterations (total), residual of the
# last step tried, max residual over good steps, max |H − H0|, max |g|, max |Gv|
F_ITERS, F_RES, F_MAXRES, F_DH, F_G, F_GV = range(6)
F_SIZE = 6


@njit
def run_member(fns, flags, Mc, prm, tabs, h, tol, max_iter, state, ws, n_total, mode, every, H0,
               Qs, Vs, Ps, En, Gr, GVr, It, ist, fst):
    """Advance one member (rows q, p, v, then scratch of ``state``) through ``n_total`` steps.

    ``mode`` is ``SAVE_FINAL`` (the final state into slot 0 of ``Qs, Vs, Ps, En``),
    ``SAVE_STRIDE`` (every ``every``-th step and the last into slots 1, 2, …, exactly as
    ``run`` fills ``outs``; slot 0 is the caller's) or ``SAVE_DIAGNOSTICS`` (the final state,
    and ``max |H − H0|``, ``max |g|``, ``max |Gv|`` over every step into ``fst``; the caller
    seeds ``fst[F_G]``, ``fst[F_GV]`` with the initial residuals). Returns the status code,
    also stored in ``ist[E_STATUS]``; a failed step's index goes to ``ist[E_FAILED]``.
    """
    q, p, v, q1, p1, v1 = state[0], state[1], state[2], state[3], state[4], state[5]
    sout = np.zeros(4)
    n = q.shape[0]
    scratch = ws[9][0]
    first = True
    win_g = 0.0
    win_gv = 0.0
    win_it = 0.0
    maxres = 0.0
    iters = 0.0
    dh = 0.0
    gmax = fst[F_G]
    gvmax = fst[F_GV]
    slot = 1
    status = 0
    k = 0
    ist[E_FAILED] = -1
    while k < n_total:
        status = step(fns, flags, Mc, prm, tabs, h, q, p, v, q1, p1, v1, ws, tol, max_iter,
                      first, sout)
        iters += sout[0]
        fst[F_RES] = sout[3]
        if status != 0:
            ist[E_FAILED] = k
            break
        first = False
        maxres = max(maxres, sout[3])
        win_g = max(win_g, sout[1])
        win_gv = max(win_gv, sout[2])
        win_it += sout[0]
        for a in range(n):
            q[a] = q1[a]
            p[a] = p1[a]
            v[a] = v1[a]
        k += 1
        if mode == SAVE_DIAGNOSTICS:
            e = energy(fns, prm, q, p, v, scratch)
            dh = max(dh, abs(e - H0))
            gmax = max(gmax, sout[1])
            gvmax = max(gvmax, sout[2])
        elif mode == SAVE_STRIDE and (k % every == 0 or k == n_total):
            for a in range(n):
                Qs[slot, a] = q[a]
                Vs[slot, a] = v[a]
                Ps[slot, a] = p[a]
            En[slot] = energy(fns, prm, q, p, v, scratch)
            Gr[slot] = win_g
            GVr[slot] = win_gv
            It[slot] = win_it
            win_g = 0.0
            win_gv = 0.0
            win_it = 0.0
            slot += 1
    if mode != SAVE_STRIDE:
        # the last good state (the final one unless the member failed)
        for a in range(n):
            Qs[0, a] = q[a]
            Vs[0, a] = v[a]
            Ps[0, a] = p[a]
        En[0] = energy(fns, prm, q, p, v, scratch)
        slot = 1
    ist[E_STATUS] = status
    ist[E_STEPS] = k
    ist[E_SAVED] = slot
    fst[F_ITERS] = iters
    fst[F_MAXRES] = maxres
    fst[F_DH] = dh
    fst[F_G] = gmax
    fst[F_GV] = gvmax
    return status


@njit(parallel=True)
def run_ensemble(fns, flags, Mc, P, tabs, h, tol, max_iter, s, r, J, X0, n_total, mode, every, H0,
                 Qs, Vs, Ps, En, Gr, GVr, It, ist, fst):
    """``run_member`` for every member ``i`` of ``X0`` (N, 3, n) = (q0, p0, v0), in parallel.

    ``P`` (N, k) holds each member's parameters; the outputs are indexed by member first
    (``Qs`` (N, K, n), ``En`` (N, K), ``ist`` (N, E_SIZE), ``fst`` (N, F_SIZE)). Each member
    gets its own workspace and state, allocated inside the loop body, so threads share
    nothing but read-only model and method data.
    """
    n = flags[0]
    m = flags[1]
    for i in prange(X0.shape[0]):
        ws = make_workspace(n, m, s, r, J)
        state = np.zeros((6, n))
        for a in range(n):
            state[0, a] = X0[i, 0, a]
            state[1, a] = X0[i, 1, a]
            state[2, a] = X0[i, 2, a]
        run_member(fns, flags, Mc, P[i], tabs, h, tol, max_iter, state, ws, n_total, mode, every,
                   H0[i], Qs[i], Vs[i], Ps[i], En[i], Gr[i], GVr[i], It[i], ist[i], fst[i])
