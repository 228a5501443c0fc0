"""The time loops: the only place that iterates over steps.

``run`` advances one trajectory by a chunk of steps (the Python driver calls it once, or in
chunks when it shows progress; the state carries everything, so chunking changes no bit).
"""

import numpy as np

from .._numba import njit
from .step import _POT, step

# layout of the float64 ``info`` vector shared with fastvi.integrate
I_STEPS, I_ITERS, I_WIN_G, I_WIN_GV, I_WIN_IT, I_RES, I_FAILED, I_SLOT, I_FIRST, I_MAXRES = range(10)
INFO_SIZE = 10


@njit
def energy(fns, prm, q, p, v, scratch):
    """H = ½ vᵀp + V(q) with v = M⁻¹p already known."""
    fns[_POT](q.ctypes, q.ctypes, prm.ctypes, scratch.ctypes)
    e = scratch[0]
    for a in range(q.shape[0]):
        e += 0.5 * v[a] * p[a]
    return e


@njit
def run(fns, flags, Mc, prm, tabs, h, tol, max_iter, state, ws, n_chunk, n_total, save_every, outs, info):
    """Advance ``state`` (rows q, p, v, then scratch) by up to ``n_chunk`` steps.

    Saves every ``save_every``-th step and the last one into ``outs`` =
    (t, q, v, p, energy, max|g|, max|Gv|, Newton iterations), the residuals and iterations
    being the maxima/sums over the steps since the previous sample. Returns a status code;
    on failure ``info[I_FAILED]`` holds the index of the step that failed.
    """
    T, Qs, Vs, Ps, En, Gr, GVr, It = outs
    q, p, v, q1, p1, v1 = state[0], state[1], state[2], state[3], state[4], state[5]
    sout = np.zeros(4)  # once per chunk, not per step
    n = q.shape[0]
    scratch = ws[9][0]
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
        info[I_MAXRES] = max(info[I_MAXRES], sout[3])
        info[I_WIN_G] = max(info[I_WIN_G], sout[1])
        info[I_WIN_GV] = max(info[I_WIN_GV], sout[2])
        info[I_WIN_IT] += sout[0]
        for a in range(n):
            q[a] = q1[a]
            p[a] = p1[a]
            v[a] = v1[a]
        k += 1
        info[I_STEPS] = k
        if k % save_every == 0 or k == n_total:
            j = int(info[I_SLOT])
            T[j] = k * h
            for a in range(n):
                Qs[j, a] = q[a]
                Vs[j, a] = v[a]
                Ps[j, a] = p[a]
            En[j] = energy(fns, prm, q, p, v, scratch)
            Gr[j] = info[I_WIN_G]
            GVr[j] = info[I_WIN_GV]
            It[j] = info[I_WIN_IT]
            info[I_WIN_G] = 0.0
            info[I_WIN_GV] = 0.0
            info[I_WIN_IT] = 0.0
            info[I_SLOT] = j + 1
    return 0
