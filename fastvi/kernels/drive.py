"""The time loops: the only place that iterates over steps.

``run`` advances one trajectory by a chunk of steps (the Python driver calls it once, or in
chunks when it shows progress; the state carries everything, so chunking changes no bit).
It is the one time loop: ``run_member`` runs an ensemble's member through it with the
member's save policy, ``run_members`` runs the members in parallel, and the linearised
flow differentiates each step from its per-step hook. The step is the one compiled entry
point of :func:`.step.step_kernel`, so a member of an ensemble equals
:func:`fastvi.integrate` of that member bit for bit by construction.
"""

from collections import namedtuple

import numba
import numpy as np
from numba import prange
from numba.core import types

from .._numba import CalledAs, byref, hot, hot_inline, njit, own, ptr
from .layout import (E_FAILED, E_SAVED, E_STATUS, E_STEPS, EVENT_SLOTS, EVENT_TERMINAL,
                     EVENTS_FULL, F_DH, F_G, F_GV, F_ITERS, F_MAXRES, F_RES, F_TSLOT, I_DH,
                     I_DRIFT, I_FAILED, I_FIRST, I_FULL, I_H0, I_ITERS, I_KR, I_MAXRES, I_RES,
                     I_SLOT, I_STEPS, I_T, I_T0, I_WIN_G, I_WIN_GV, I_WIN_IT, I_WORK,
                     I_WORK_F, INFO_SIZE, NEEDS_FULL_NEWTON, POT, S_FULL, S_G, S_GV, S_ITERS,
                     S_RES, S_WORK, S_WORK_F, SAVE_DIAGNOSTICS, SAVE_STRIDE,
                     STEP_OUT_SIZE, Events, ModelData, Samples, dim, is_timed, sizes,
                     with_plan, workspace_shaped)
from .adapt import advance, finished, next_step
from .events import after_step, event_values, room_for_crossings
from .._launch import _key
from .step import cached_cfunc

__all__ = ["run", "run_member", "run_members", "EnsembleMembers", "member_function",
           "ensemble_member", "energy", "accept", "record", "step_hook", "c_entry", "INFO_SIZE"]


@hot
def energy(md, t, q, p, v, scratch):
    """H = ½ vᵀp + V(t, q) with v = M⁻¹p already known."""
    if is_timed(md):
        md.prm[md.flags[F_TSLOT]] = t
    md.fns[POT](ptr(q), ptr(q), ptr(md.prm), ptr(scratch))
    e = scratch[0]
    for a in range(q.shape[0]):
        e += 0.5 * v[a] * p[a]
    return e


@hot
def record(md, t, state, ws, smp, slot, info):
    """Write the state (rows q, p, v) at time ``t`` into sample ``slot`` with the residual
    windows and the work of ``info``, and open new windows."""
    q, p, v = state[0], state[1], state[2]
    for a in range(q.shape[0]):
        smp.q[slot, a] = q[a]
        smp.v[slot, a] = v[a]
        smp.p[slot, a] = p[a]
    smp.t[slot] = t
    smp.energy[slot] = energy(md, t, q, p, v, ws.g)
    smp.work[slot] = info[I_WORK]
    smp.work_forces[slot] = info[I_WORK_F]
    smp.g[slot] = info[I_WIN_G]
    smp.gv[slot] = info[I_WIN_GV]
    smp.iters[slot] = info[I_WIN_IT]
    info[I_WIN_G] = 0.0
    info[I_WIN_GV] = 0.0
    info[I_WIN_IT] = 0.0


@hot_inline
def accept(md, t1, last, state, ws, save_every, smp, info, sout):
    """Book-keeping after a step has been taken (state rows 0–2 already hold the new state,
    at time ``t1``): counters, residual windows, and the sample when one is due (every
    ``save_every``-th step, and the ``last``)."""
    info[I_MAXRES] = max(info[I_MAXRES], sout[S_RES])
    info[I_WIN_G] = max(info[I_WIN_G], sout[S_G])
    info[I_WIN_GV] = max(info[I_WIN_GV], sout[S_GV])
    info[I_WIN_IT] += sout[S_ITERS]
    info[I_FULL] += sout[S_FULL]
    info[I_WORK] += sout[S_WORK]
    info[I_WORK_F] += sout[S_WORK_F]
    k = int(info[I_STEPS]) + 1
    info[I_STEPS] = k
    if save_every > 0 and (k % save_every == 0 or last):
        j = int(info[I_SLOT])
        record(md, t1, state, ws, smp, j, info)
        info[I_SLOT] = j + 1


@hot_inline
def _last_sample(md, t1, state, ws, n_total, save_every, smp, info):
    """After a terminal event: the step that contains it (ending at ``t1``) becomes the
    last sample (unless ``accept`` already saved it)."""
    k = int(info[I_STEPS])
    if save_every > 0 and k % save_every != 0 and k != n_total:
        j = int(info[I_SLOT])
        record(md, t1, state, ws, smp, j, info)
        info[I_SLOT] = j + 1


@hot_inline
def _clock(ws, info, h):
    """Set the times of the next step in ``ws.time``: step k runs from t0 + k h to
    t0 + (k+1) h, each computed from t0 (no drift). Returns k."""
    k = int(info[I_STEPS])
    ws.time[0] = info[I_T0] + k * h
    ws.time[1] = info[I_T0] + (k + 1) * h
    return k


@hot_inline
def _book(status, k, state, ws, info, sout):
    """After step ``k`` (status ``status``): counters, and on success the new state copied
    into state rows 0–2."""
    info[I_ITERS] += sout[S_ITERS]
    info[I_RES] = sout[S_RES]
    if status != 0:
        info[I_FAILED] = k
        return status
    info[I_FIRST] = 0.0
    for a in range(sizes(ws)[0]):
        state[0, a] = state[3, a]
        state[1, a] = state[4, a]
        state[2, a] = state[5, a]
    return 0


@hot
def run(md, tabs, opts, h, state, ws, n_chunk, n_total, save_every, smp, info, sout, ev,
        stepk, stages, events=None, each=None, each_data=None):
    """Advance ``state`` (rows q, p, v, then scratch) by up to ``n_chunk`` steps, step k
    running from ``info[I_T0] + k h``; ``sout`` is the step's output scratch
    (``STEP_OUT_SIZE``); ``ev`` the :class:`.layout.Events` of the run (no events and no
    dense rows: the event code is skipped by one test per chunk). Events are a run-time
    switch: a type-level one would compile the loop twice, and one test a chunk costs
    nothing measurable.

    The time loop is ``hot`` (no reference counting) with the bookkeeping inlined: with
    reference counting on, the inlined helpers' array views cost 15 % of a step; without
    it, inlining saves the flattened-argument copies of two calls a step (7–10 % on
    ``P2L-Q3G``/``P3L-Q4G``, docs/decisions/0006-kernels-without-reference-counting.md).

    Saves every ``save_every``-th step and the last one into the :class:`Samples` ``smp``,
    the residuals and iterations being the maxima/sums over the steps since the previous
    sample. Returns a status code; on failure ``info[I_FAILED]`` holds the failed step;
    ``EVENT_TERMINAL`` after the step in which a terminal event fired, ``EVENTS_FULL``
    before a step when an event record has no room left.

    ``stepk``, ``stages``: the compiled step for these argument types and the stages it
    calls (:func:`.step.step_kernel`), called through its address with pointers to the
    named tuples (:func:`.byref`).

    ``events``: None for a run without events or dense output, whose loop is then compiled
    without the event code (numba prunes what an argument that is None guards); True for
    records that the driver grows (``EVENTS_FULL`` before a step that could overflow one);
    False for records of fixed length that count the crossings past their end without
    keeping them (an ensemble member's).

    With ``info[I_DRIFT]`` non-zero, ``info[I_DH]`` becomes the maximum over the steps of
    ``|H − info[I_H0] − W|`` (W the work of forces and time): the diagnostics save policy
    of ensembles, which keep no samples but such maxima. A run-time switch, not an
    argument: an ensemble's member then calls this loop with the argument types of
    :func:`fastvi.integrate`, whose compiled loop it shares.

    ``each``: None, or a C function ``each(mdp, h, k, statep, wsp, infop, slot, datap)``
    (:func:`step_hook`) called after every accepted step ``k`` with pointers to ``md``,
    ``state`` (rows 0–2 and 3–5 both hold the new state), ``ws`` (the step's unknowns),
    ``info``, and ``each_data``, the hook's own data as an untyped pointer
    (:func:`fastvi._numba.erased`: one compiled loop serves every hook);
    ``slot`` is ``info[I_SLOT]`` before the step, so a sample was saved if it grew. It returns
    a status code; a non-zero one ends the run with ``info[I_FAILED] = k``. The linearised
    flow differentiates each step this way (:mod:`.tangent`), in this one time loop: its
    step-by-step calls of ``run`` had cost more than a step each, in the copies of the
    named tuples passed by value. None compiles the loop without the call.

    Adaptive steps (``info[I_KR] > 0``, another run-time switch): ``h`` is then ε, step k
    has the length of :func:`.adapt.next_step` and the run ends at ``info[I_TEND]``
    (``n_total`` only caps the steps); each sample is saved at the time reached.
    """
    active = ev.count > 0 or ev.dense.shape[0] > 0
    adaptive = info[I_KR] > 0.0
    # the step reads the model, tables and workspace through pointers: one word each
    # instead of their flattened fields copied at every call (_numba.byref)
    mdp, tabp, optp, wsp = byref(md), byref(tabs), byref(opts), byref(ws)
    statep, soutp, stagesp = byref(state), byref(sout), byref(stages)
    if each is not None:
        infop, datap = byref(info), each_data
    hk = h
    for _ in range(n_chunk):
        k = int(info[I_STEPS])
        if k >= n_total or finished(info):
            break
        if events is not None:
            if active:
                if events and not room_for_crossings(ev):
                    return EVENTS_FULL
                for a in range(state.shape[1]):
                    ev.qk[a] = state[0, a]
        if adaptive:
            hk = next_step(md, h, state, ws, info)
        else:
            _clock(ws, info, h)
        first = info[I_FIRST] != 0.0
        status = stepk(mdp, tabp, optp, hk, statep, wsp, first, soutp, stagesp)
        if status == NEEDS_FULL_NEWTON:
            return status  # nothing booked: the driver retakes step k with the full Newton
        status = _book(status, k, state, ws, info, sout)
        if status != 0:
            return status
        est = 0
        if events is not None:
            if active:
                est = after_step(md, tabs, h, ws.time[0], ws.time[1], k, ev.qk, ws.X, state, ev)
        if adaptive:
            advance(md, h, hk, state, ws, info)
            accept(md, info[I_T], finished(info), state, ws, save_every, smp, info, sout)
        else:
            if each is not None:
                slot = int(info[I_SLOT])
            accept(md, ws.time[1], k + 1 == n_total, state, ws, save_every, smp, info, sout)
            if each is not None:
                status = each(mdp, h, k, statep, wsp, infop, slot, datap)
                if status != 0:
                    info[I_FAILED] = k
                    return status
        if info[I_DRIFT] != 0.0:
            e = energy(md, ws.time[1], state[0], state[1], state[2], ws.g)
            info[I_DH] = max(info[I_DH], abs(e - info[I_H0] - info[I_WORK]))
        if est != 0:
            _last_sample(md, ws.time[1], state, ws, n_total, save_every, smp, info)
            return est
    return 0


#: the compiled per-step hooks of :func:`run`, by function and argument types
_HOOKS = {}


def step_hook(fn, md, state, ws, info, data, data_type, compile=True):
    """``fn(mdp, h, k, statep, wsp, infop, slot, datap)`` compiled as a C function (cached
    on disk) for the types of ``md``, ``state``, ``ws``, ``info`` and of the hook's data,
    made of the values ``data`` and typed ``data_type()`` (a numba type): the ``each`` hook
    of :func:`run`. A C function rather than a compiled Python function passed as an
    argument: numba cannot cache a loop compiled for a function argument, while this one is
    typed by its signature alone. Found again by the arguments' type fingerprints
    (:func:`fastvi._launch._key`): building numba's types costs milliseconds a call.

    With ``compile`` false, the hook only if it is compiled already (in this process or in
    numba's disk cache), else None.

    :func:`run` types the hook with ``datap`` an untyped pointer (``void*``, what the
    caller passes: :func:`fastvi._numba.erased`), the same machine word: one compiled time
    loop then serves every hook (the sensitivities' and the adjoint's), where a loop typed
    by each hook's data took 7–8 s of compiling each."""
    key = (fn,) + tuple(_key(x) for x in (md, state, ws, info, *data))
    P, typeof = types.CPointer, numba.typeof
    return c_entry(key, lambda: (P(typeof(md)), types.float64, types.int64, P(typeof(state)),
                                 P(typeof(ws)), P(typeof(info)), types.int64),
                   fn, data_type, compile)


#: the keys of :func:`c_entry` looked up in numba's disk cache and not found, in this process
_NOT_CACHED = set()


def c_entry(key, head, fn, data_type, compile=True):
    """``fn(*head, datap)`` as a C function (cached on disk), ``datap`` a pointer to a
    record of the numba type ``data_type()``, called as ``fn(*head, void*)``: one type
    for every record, so that its caller is compiled once for all of them. Kept by
    ``key``; with ``compile`` false, None unless compiled already (:func:`step_hook`)."""
    hook = _HOOKS.get(key)
    if hook is None:
        if not compile and key in _NOT_CACHED:
            return None  # looked up once: a lookup costs a few ms
        head = head()
        cf = cached_cfunc(fn, types.int64(*head, types.CPointer(data_type())), compile)
        if cf is None:
            _NOT_CACHED.add(key)
            return None
        hook = _HOOKS[key] = CalledAs(cf, types.int64(*head, types.voidptr))
    return hook


# ----------------------------------------------------------------------------- ensembles
@hot
def run_member(md, tabs, opts, h, t0, state, ws, n_total, mode, every, H0, smp, ist, fst, sout,
               info, ev, stepk, stages):
    """Advance one member (rows q, p, v, then scratch of ``state``) through ``n_total`` steps
    of the one time loop :func:`run`, with the member's save policy.

    ``mode`` is ``SAVE_FINAL`` (the final state into slot 0 of ``smp``), ``SAVE_STRIDE``
    (every ``every``-th step and the last into slots 1, 2, …, exactly as ``run`` fills its
    samples; slot 0 is the caller's) or ``SAVE_DIAGNOSTICS`` (the final state, and
    ``max |H − H0 − W|`` (W the work of forces and time, zero for a conservative model),
    ``max |g|``, ``max |Gv + g_t|`` over every step into ``fst``; the caller
    seeds ``fst[F_G]``, ``fst[F_GV]`` with the initial residuals). Returns the status code,
    also stored in ``ist[E_STATUS]``; a failed step's index goes to ``ist[E_FAILED]``.

    ``ev`` holds the member's event records (``count = 0``: none; no dense rows), of fixed
    length: a record that is full counts further crossings without keeping them. A terminal
    event ends the member after the step that contains it (status ``EVENT_TERMINAL``); in
    stride mode that step is then the last sample, as in :func:`fastvi.integrate`.

    ``stepk``, ``stages``: the compiled step (:func:`.step.step_kernel`), the very one
    :func:`fastvi.integrate` of that member calls: the same step, bit for bit.
    """
    for k in range(INFO_SIZE):
        info[k] = 0.0
    info[I_FIRST] = 1.0
    info[I_SLOT] = 1.0
    info[I_T0] = t0
    stride = every if mode == SAVE_STRIDE else 0
    if ev.count > 0:
        event_values(md, ev, t0, state[0], state[2])
    info[I_DRIFT] = 1.0 if mode == SAVE_DIAGNOSTICS else 0.0
    info[I_H0] = H0
    # the argument types of integrate's call (events: a run-time bool, False here, for
    # fixed-length records; None as Python passes the defaults), so that both share one
    # compiled loop
    grow = ev.count < 0
    status = run(md, tabs, opts, h, state, ws, n_total, n_total, stride, smp, info, sout, ev,
                 stepk, stages, grow, None, None)
    fst[F_RES] = sout[S_RES]
    failed = status != 0 and status != EVENT_TERMINAL
    if status == NEEDS_FULL_NEWTON:  # the members' step takes the full Newton itself
        info[I_FAILED] = info[I_STEPS]
    ist[E_FAILED] = int(info[I_FAILED]) if failed else -1
    if mode == SAVE_DIAGNOSTICS:
        # no sample was saved, so the residual windows span every step taken
        fst[F_G] = max(fst[F_G], info[I_WIN_G])
        fst[F_GV] = max(fst[F_GV], info[I_WIN_GV])
    slot = int(info[I_SLOT])
    if mode != SAVE_STRIDE:
        # the last good state (the final one unless the member failed)
        record(md, t0 + info[I_STEPS] * h, state, ws, smp, 0, info)
        slot = 1
    ist[E_STATUS] = status
    ist[E_STEPS] = int(info[I_STEPS])
    ist[E_SAVED] = slot
    fst[F_ITERS] = info[I_ITERS]
    fst[F_MAXRES] = info[I_MAXRES]
    fst[F_DH] = info[I_DH]
    return status


EnsembleMembers = namedtuple("EnsembleMembers", [
    "fns", "flags", "Mc", "P", "tabs", "opts", "h", "t0", "dims", "si", "sb", "shapes",
    "X0", "n_total", "mode", "every", "H0", "Qs", "Vs", "Ps", "En", "Gr", "GVr", "It", "Wk",
    "ist", "fst", "efns", "ecount", "edir", "eterm", "Te", "Qe", "Ve", "Ne", "stepk",
    "stages"])
EnsembleMembers.__doc__ = """The ensemble of :func:`fastvi.integrate_ensemble`: :func:`run_member`
    for every member ``i`` of ``X0`` (N, 3, n) = (q0, p0, v0), in parallel (:func:`run_members` with
    :func:`_ensemble_member`).

    ``dims`` = (n, m, s, r, J) sizes each member's workspace (the stages in ``stages`` may
    be compiled for these sizes: :func:`.step.step_kernel`), ``shapes`` its arrays' shapes
    (:func:`.layout.field_shapes` of a single run's workspace with the full Newton, which
    the members take without returning to Python), and ``si``, ``sb`` the structured-solve
    plan of that workspace (:func:`fastvi.structure.workspace`; each member solves with
    its own copy of ``sb``, in a workspace typed as the step's loop view,
    :func:`.layout.loop_view`). ``P``
    (N, k + 1) holds each member's kernel parameters (the kernels write the time into the
    last entry of a member's own row); the
    outputs are indexed by
    member first (``Qs`` (N, K, n), ``En``, ``Wk`` (N, K), ``ist`` (N, E_SIZE), ``fst``
    (N, F_SIZE)). Each member gets its own workspace and state, allocated inside the loop
    body, so threads share nothing but read-only model and method data.

    Events: ``efns`` (EVENT_SLOTS callbacks, the first ``ecount`` used), ``edir``, ``eterm``
    as in :class:`.layout.Events`; member ``i`` keeps its first ``Te.shape[2]`` crossings of
    each event in ``Te[i]`` (E, K), ``Qe[i]``, ``Ve[i]`` (E, K, n) and counts all of them in
    ``Ne[i]`` (EVENT_SLOTS,). ``stepk`` is the compiled step for a member's workspace
    and its stages (:func:`.step.step_kernel`)."""


def _ensemble_member(i, gp):
    """Member ``i`` of an :class:`EnsembleMembers` (a body of :func:`member_function`): its
    own workspace, state, samples and event records, then :func:`run_member`."""
    g = own(gp)
    n = dim(g.dims[0])
    s = dim(g.dims[2])
    ws = with_plan(workspace_shaped(g.dims, g.shapes), g.si, g.sb.copy(), None)
    state = np.zeros((6, n))
    for a in range(n):
        state[0, a] = g.X0[i, 0, a]
        state[1, a] = g.X0[i, 1, a]
        state[2, a] = g.X0[i, 2, a]
    # the member's times are the caller's grid, so they go to scratch
    K = g.En.shape[1]
    smp = Samples(np.zeros(K), g.Qs[i], g.Vs[i], g.Ps[i], g.En[i], g.Gr[i], g.GVr[i], g.It[i],
                  g.Wk[i], np.zeros(K))
    ev = Events(g.efns, g.ecount, g.edir, g.eterm, np.zeros(EVENT_SLOTS), g.Te[i], g.Qe[i],
                g.Ve[i], g.Ne[i], np.zeros((0, s + 1, n)), np.zeros((s + 1, n)), np.zeros(n),
                np.zeros(n), np.zeros(n), np.zeros(s + 1), np.zeros(s + 1), np.zeros(1))
    return run_member(ModelData(g.fns, g.flags, g.Mc, g.P[i]), g.tabs, g.opts, g.h, g.t0,
                      state, ws, g.n_total, g.mode, g.every, g.H0[i], smp, g.ist[i], g.fst[i],
                      np.zeros(STEP_OUT_SIZE), np.zeros(INFO_SIZE), ev, g.stepk, g.stages)


#: the compiled members, by body and the fingerprint of their data's types
_MEMBERS = {}


def member_function(body, group):
    """``body(i, gp) -> status`` (member ``i`` of the ensemble whose data ``gp`` points to)
    compiled as a C function (cached on disk, with reference counting: a member allocates
    its own workspaces) for the types of ``group``: what :func:`run_members` calls for each
    member. Bodies: :func:`_ensemble_member` (:func:`fastvi.integrate_ensemble`) and
    :func:`.tangent.tangent_member` (:func:`fastvi.sensitivity_ensemble`).

    A C function called by address, so that the parallel kernel holds one call and a
    pointer: with a member's set-up and time loop in the body of the ``prange`` loop,
    numba's parallel lowering compiled the loop again there
    (``docs/decisions/0015-ensemble-members.md``)."""
    key = (body, _key(group))
    member = _MEMBERS.get(key)
    if member is None:
        sig = types.int64(types.int64, types.CPointer(numba.typeof(group)))
        member = _MEMBERS[key] = cached_cfunc(body, sig, allocates=True)
    return member


@njit(parallel=True)
def run_members(member, group, status):
    """``status[i] = member(i, &group)`` for every member ``i`` in parallel: the one
    ``prange`` driver of the ensembles (``member`` from :func:`member_function`). Each member
    allocates its own workspaces and writes only its own rows of ``group``'s arrays, so
    threads share nothing written."""
    gp = byref(group)
    for i in prange(status.shape[0]):
        status[i] = member(np.int64(i), gp)  # prange counts in uint64


def ensemble_member(group):
    """The member of :func:`fastvi.integrate_ensemble` for an :class:`EnsembleMembers`."""
    return member_function(_ensemble_member, group)
