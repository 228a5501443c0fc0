"""Drive the step kernel directly from a test: one step of a model from (q, p, v)."""

import numpy as np

from fastvi.kernels import layout as lay
from fastvi.kernels.step import step_once


def one_step(model, meth, h, q, p, v, *, ws=None, first=True, tol=1e-14, max_iter=30,
             newton="auto", params=None):
    """Returns ``(status, q1, p1, v1, out, ws)`` after one call of the step kernel."""
    n = model.n
    if ws is None:
        ws = lay.make_workspace(n, model.m, meth.s, meth.r, meth.J)
    md = model.kernel_data(params)
    opts = lay.NewtonOptions(tol, max_iter, lay.NEWTON_MODES[newton])
    state = np.zeros((6, n))
    state[0], state[1], state[2] = q, p, v
    out = np.zeros(lay.STEP_OUT_SIZE)
    st = step_once(md, meth.kernel_tables, opts, h, state, ws, first, out)
    return st, state[3].copy(), state[4].copy(), state[5].copy(), out, ws
