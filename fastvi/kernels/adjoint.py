r"""The discrete adjoint: the transposed linearised steps swept backwards, with checkpoints.

For a cost ``J`` of the saved states, with ``Λ_i = (∂J/∂q_i, ∂J/∂p_i)`` at sample ``i``,
the adjoint of step k (:func:`.tangent.pull`) maps ``λ_{k+1}`` to

    λ_k = (∂x_{k+1}/∂x_k)ᵀ λ_{k+1} + Λ(k),      ∇_θ J += (∂x_{k+1}/∂θ)ᵀ λ_{k+1},

``Λ(k)`` the cotangent of the sample at step k, if any: one transposed solve with the
step's exact Newton matrix a step, whatever the number of parameters. The backward sweep
needs each step's converged unknowns. :func:`run_checkpointed` keeps the step's state and
the predictor's history at the start of each segment of ``C`` steps, and records each
segment's steps into :class:`Records` as it goes; :func:`run_adjoint` sweeps the segment the
forward run recorded last as it is, and retakes every other segment from its checkpoint —
the same steps, bit for bit — before sweeping it backwards. The segments end at
``N, N − C, N − 2C, …``: the first one is the short one (:func:`_offset`), so that the
segment the forward run leaves recorded is a whole one. Memory is ``∝ N / C + C`` and time
``N − C`` steps more than the forward run: with ``C = N`` (every step kept) nothing is
retaken.
"""

from collections import namedtuple

import numpy as np

import numba
from numba.core import types

from .._numba import byref, erased, hot, hot_inline, own
from .._launch import _key
from .drive import c_entry, run, step_hook
from .layout import H_SIZE, I_FAILED, I_FIRST, I_STEPS, OK, SI_GCOL, SI_GPTR, sizes
from .tangent import LINEARISED_TYPE, linearisation_args, linearised, pull, sized_entry

__all__ = ["Checkpoints", "Records", "g_entries", "make_checkpoints", "make_records",
           "run_checkpointed", "run_adjoint", "recorder", "sweeper", "Sweep"]

#: what a step needs of the past to be retaken bit for bit: the state (rows q, p, v), the
#: predictor's unknowns of the last two steps, the workspace's flags and step lengths, and
#: G(q_k) (the step reuses the last one's), over G's pattern where the plan has one
#: (:func:`g_entries`); per checkpoint, with the step it starts
Checkpoints = namedtuple("Checkpoints", ["steps", "first", "state", "Xprev", "Xpp", "hold",
                                         "hist", "G0"])
#: the steps of one segment: start (q_k, p_k), converged unknowns, times, end (q, v), end
#: impulse and momentum before the projection — what :func:`.tangent.linearise` reads
Records = namedtuple("Records", ["qk", "pk", "X", "time", "q1", "v1", "eta", "P"])
#: the records of the segment that starts at step ``k0``
Recording = namedtuple("Recording", ["rec", "k0"])


def g_entries(ws):
    """The entries of G(q) a checkpoint keeps: those of G's pattern in the workspace's plan
    (``ws.si``), else all ``m n``."""
    n, m = sizes(ws)[:2]
    gp = int(ws.si[SI_GPTR])
    return int(ws.si[gp + m]) if gp != 0 else max(m, 1) * n


def make_checkpoints(count, n, m, N, g_size):
    z = np.zeros
    return Checkpoints(z(count, dtype=np.int64), z(count), z((count, 3, n)), z((count, N)),
                       z((count, N)), z((count, H_SIZE), dtype=np.int64), z((count, 2)),
                       z((count, g_size)))


@hot_inline
def _g_pattern(ws, G0, out, to_workspace):
    """Copy G(q_k) between the workspace's ``G0`` (m, n) and a checkpoint's ``out``
    (:func:`g_entries`), over G's pattern where the plan has one: outside it G is zero."""
    si = ws.si
    gp = si[SI_GPTR]
    e = 0
    for c in range(G0.shape[0]):
        lo, hi = (si[gp + c], si[gp + c + 1]) if gp != 0 else (0, G0.shape[1])
        for k in range(lo, hi):
            a = si[si[SI_GCOL] + k] if gp != 0 else k
            if to_workspace:
                G0[c, a] = out[e]
            else:
                out[e] = G0[c, a]
            e += 1


def make_records(C, n, m, N):
    z = np.zeros
    return Records(z((C, n)), z((C, n)), z((C, N)), z((C, 2)), z((C, n)), z((C, n)),
                   z((C, max(m, 1))), z((C, n)))


@hot
def _keep(ck, i, state, ws, info):
    ck.steps[i] = int(info[I_STEPS])
    ck.first[i] = info[I_FIRST]
    for r in range(3):
        for a in range(state.shape[1]):
            ck.state[i, r, a] = state[r, a]
    for k in range(ws.Xprev.shape[0]):
        ck.Xprev[i, k] = ws.Xprev[k]
        ck.Xpp[i, k] = ws.Xpp[k]
    for k in range(ws.hold.shape[0]):
        ck.hold[i, k] = ws.hold[k]
    ck.hist[i, 0] = ws.hist[0]
    ck.hist[i, 1] = ws.hist[1]
    _g_pattern(ws, ws.G[0], ck.G0[i], False)


@hot
def _restore(ck, i, state, ws, info):
    info[I_STEPS] = ck.steps[i]
    info[I_FIRST] = ck.first[i]
    for r in range(3):
        for a in range(state.shape[1]):
            state[r, a] = ck.state[i, r, a]
    for k in range(ws.Xprev.shape[0]):
        ws.Xprev[k] = ck.Xprev[i, k]
        ws.Xpp[k] = ck.Xpp[i, k]
    for k in range(ws.hold.shape[0]):
        ws.hold[k] = ck.hold[i, k]
    ws.hist[0] = ck.hist[i, 0]
    ws.hist[1] = ck.hist[i, 1]
    _g_pattern(ws, ws.G[0], ck.G0[i], True)


@hot
def _segment(md, tabs, opts, h, state, ws, k0, cnt, n_total, every, smp, info, sout, ev,
             stepk, stages, rec, each):
    """The steps of :func:`.drive.run` from the state of step ``info[I_STEPS]`` to step
    ``k0 + cnt``, each recorded into ``rec``, the records of the segment that starts at
    step ``k0``, by ``each`` (the :func:`recorder`); the segment's start too, if it starts
    here. Returns a status code."""
    if int(info[I_STEPS]) == k0:
        for a in range(state.shape[1]):
            rec.qk[0, a] = state[0, a]
            rec.pk[0, a] = state[1, a]
    return run(md, tabs, opts, h, state, ws, k0 + cnt - int(info[I_STEPS]), n_total, every,
               smp, info, sout, ev, stepk, stages, None, each,
               erased(byref(Recording(rec, k0))))


@hot_inline
def _offset(n_total, C):
    """``o`` with segment ``i`` the steps ``max(iC − o, 0) … (i + 1)C − o − 1``: segment
    ``i`` holds step ``k`` for ``i = (k + o) // C``, and only the first is shorter than
    ``C``."""
    return ((n_total + C - 1) // C) * C - n_total


@hot
def run_checkpointed(md, tabs, opts, h, state, ws, n_total, save_every, smp, info, sout, ev,
                     stepk, stages, ck, rec, each, stop):
    """:func:`.drive.run` in segments of at most ``C`` steps (``rec`` holds ``C``; the
    first is the short one, :func:`_offset`), keeping a checkpoint before each in ``ck``
    (``ceil(n_total / C)`` of them) and recording each segment into ``rec`` by ``each``
    (the :func:`recorder`): at the end ``rec`` holds the last segment, ``C`` steps that
    :func:`run_adjoint` then needs not retake. Up to step ``stop``: a call continues where
    the last one stopped (a progress display between them). Returns a status code."""
    C = rec.qk.shape[0]
    off = _offset(n_total, C)
    end = min(stop, n_total)
    while int(info[I_STEPS]) < end:
        i = (int(info[I_STEPS]) + off) // C
        k0 = max(i * C - off, 0)
        if int(info[I_STEPS]) == k0:
            _keep(ck, i, state, ws, info)
        st = _segment(md, tabs, opts, h, state, ws, k0, min((i + 1) * C - off, end) - k0,
                      n_total, save_every, smp, info, sout, ev, stepk, stages, rec, each)
        if st != 0:
            return st
    return 0


@hot
def _sample_of(k, every, n_total, K):
    """The sample that holds the state after ``k`` steps, or −1."""
    if k % every == 0:
        return k // every
    if k == n_total:
        return K - 1
    return -1


def _record(mdp, h, k, statep, wsp, infop, slot, recp):
    """After step ``k`` of a retaken segment (the per-step hook of :func:`.drive.run`,
    :func:`recorder`): its unknowns, times, end and impulse into ``rec`` at ``k − k0``, and
    its end as the next step's start."""
    state, ws, r = own(statep), own(wsp), own(recp)
    rec = r.rec
    j = k - r.k0
    n = state.shape[1]
    for i in range(ws.X.shape[0]):
        rec.X[j, i] = ws.X[i]
    rec.time[j, 0] = ws.time[0]
    rec.time[j, 1] = ws.time[1]
    for a in range(n):
        rec.q1[j, a] = state[3, a]
        rec.v1[j, a] = state[5, a]
        rec.P[j, a] = ws.P[a]
    for c in range(sizes(ws)[1]):
        rec.eta[j, c] = ws.etaJ[c]
    if j + 1 < rec.qk.shape[0]:
        for a in range(n):
            rec.qk[j + 1, a] = state[0, a]
            rec.pk[j + 1, a] = state[1, a]
    return OK


#: what a step of the backward sweep (:func:`_sweep_step`) reads besides the model: pointers
#: to the extended tables and the TangentWork, the records, the cotangent ``(lq, lp)`` and
#: the parameters' gradient ``lth``, and the :func:`.tangent.linearised` step
Sweep = namedtuple("Sweep", ["txp", "twp", "rec", "lq", "lp", "lth", "lin"])


def _sweep_step(mdp, h, j, sweepp):
    """Step ``j`` of the records swept back: :func:`.tangent.linearise` at it, then
    :func:`.tangent.pull` of the cotangent. Returns a status code."""
    sw = own(sweepp)
    tw, rec = own(sw.twp), sw.rec
    m = sizes(tw.ws)[1]
    for a in range(tw.qk.shape[0]):
        tw.qk[a] = rec.qk[j, a]
        tw.pk[a] = rec.pk[j, a]
    argsp = byref(linearisation_args(sw.lin, sw.txp, sw.twp, rec.time[j], rec.X[j], rec.q1[j],
                                     rec.v1[j], rec.eta[j, :m], rec.P[j]))
    st = sw.lin.step(erased(mdp), h, erased(argsp))
    if st == OK:
        st = pull(mdp, h, argsp, sw.lq, sw.lp, sw.lth)
    return st


def sweeper(md, tx, tw, rec, lth, sized=False):
    """:func:`_sweep_step` compiled as a C function for these argument types, called by
    :func:`run_adjoint` through its address, and the :func:`.tangent.linearised` step it
    calls: ``(back, lin)``. The sweep's loop is then
    compiled once for the generic and the sized linearised step (``sized`` as in
    :func:`.tangent.differentiator`)."""
    twin = sized_entry(_sweeper, (md, tx, tw, rec, lth), md, tx, tw, sized)
    return twin or (_sweeper(md, tx, tw, rec, lth, True), linearised(md, tx, tw))


def _sweeper(md, tx, t, rec, lth, compile):
    P, typeof = types.CPointer, numba.typeof
    key = (_sweep_step,) + tuple(_key(x) for x in (md, tx, t, rec, lth))
    return c_entry(key, lambda: (P(typeof(md)), types.float64, types.int64), _sweep_step,
                   lambda: types.NamedTuple([P(typeof(tx)), P(typeof(t)), typeof(rec),
                                             typeof(lth), typeof(lth), typeof(lth),
                                             LINEARISED_TYPE], Sweep),
                   compile)


def recorder(md, state, ws, info, rec):
    """:func:`_record` compiled as the per-step hook of :func:`.drive.run`
    (:func:`.drive.step_hook`) for these argument types: what :func:`run_adjoint` passes."""
    return step_hook(_record, md, state, ws, info, (rec,),
                     lambda: types.NamedTuple([numba.typeof(rec), types.int64], Recording))


@hot
def run_adjoint(md, tabs, tx, opts, h, state, ws, n_total, every, smp, info, sout, ev, stepk,
                stages, tw, ck, rec, Lq, Lp, lq, lp, lth, each, back, lin, k_hi, k_lo):
    """The backward sweep over the steps ``k_hi − 1`` down to ``k_lo``: the cotangent
    ``(lq, lp)`` after step ``k_hi`` becomes the one at step ``k_lo`` for the sample
    cotangents ``Lq``, ``Lp`` (K, n) (at step 0: ``λ_0``), and ``lth`` (np,) gains the
    gradient by the parameters ``tw.pidx`` through those steps. A sweep from ``n_total`` to
    0 in several calls, each continuing where the last one stopped, equals one call (a
    progress display between them). Each segment of ``ck`` (:func:`run_checkpointed`) is
    swept backwards with :func:`.tangent.linearise` and :func:`.tangent.pull` (by
    ``back`` and ``lin``, the :func:`sweeper`'s): the last one from ``rec`` as the forward run left it,
    the others retaken into ``rec`` (by ``each``, the :func:`recorder`) from their
    checkpoints when the sweep reaches their last step.
    Returns a status code; ``info[I_FAILED]`` is the failed step."""
    mdp = byref(md)
    sw = erased(byref(Sweep(byref(tx), byref(tw), rec, lq, lp, lth, lin)))
    n = state.shape[1]
    C = rec.qk.shape[0]
    K = Lq.shape[0]
    nseg = (n_total + C - 1) // C
    off = _offset(n_total, C)
    no_samples = nseg - nseg  # an int64 of run time: a literal would compile `run` again
    for k in range(k_hi - 1, k_lo - 1, -1):
        seg = (k + off) // C
        k0 = ck.steps[seg]
        j = k - k0
        k1 = (seg + 1) * C - off  # the segment's end
        if seg < nseg - 1 and k == k1 - 1:
            _restore(ck, seg, state, ws, info)
            st = _segment(md, tabs, opts, h, state, ws, k0, k1 - k0, n_total, no_samples, smp,
                          info, sout, ev, stepk, stages, rec, each)
            if st != 0:
                return st
        i = _sample_of(k + 1, every, n_total, K)
        if i >= 0:
            for a in range(n):
                lq[a] += Lq[i, a]
                lp[a] += Lp[i, a]
        st = back(mdp, h, j, sw)
        if st != OK:
            info[I_FAILED] = k
            return st
    if k_lo == 0:
        for a in range(n):
            lq[a] += Lq[0, a]
            lp[a] += Lp[0, a]
    return 0
