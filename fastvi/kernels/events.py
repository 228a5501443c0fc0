r"""Dense output and event location inside the time loop.

After each accepted step the driver hands this module the step's polynomial
``q(τ) = Σ_ν Q^ν ℓ_ν(τ)`` (``Q^0 = q_k``, ``Q^ν = q_k + ΔQ^ν``), ``v(τ) = (1/h) Σ_ν Q^ν ℓ'_ν(τ)``,
``τ ∈ [0, 1]``. It

* stores the control points for :attr:`fastvi.Result.sol` (``dense`` output), and
* evaluates the event functions at the new grid state ``(t_{k+1}, q_{k+1}, v_{k+1})``; a sign
  change from the previous grid value (filtered by ``direction``) is a crossing inside the
  step, located on the polynomial by the Illinois variant of regula falsi to round-off in
  ``t``. Grid values are computed once and reused as the next step's start, so a crossing is
  counted once, also when it falls exactly on a grid point (a value of exactly zero ends a
  crossing; a start at exactly zero does not begin one). A NaN value means "undefined
  here": no crossing is counted into or out of it, which lets an event watch only part of
  the configuration space (e.g. a rod's horizontal position only while it points upwards).

A record that is full (an ensemble member keeps a fixed number of crossings per event)
still counts a crossing in ``n`` (and towards ``terminal``) without locating it.

Nothing here allocates; the event records are preallocated by the Python driver, which
grows them when :data:`EVENTS_FULL` asks for room (the state carries everything, so that
changes no bit).
"""

from .._numba import hot, hot_inline, ptr
from .layout import EVENT_TERMINAL, F_N, F_TSLOT

__all__ = ["event_values", "after_step", "room_for_crossings"]

_ILLINOIS_MAX = 100


@hot_inline
def _basis(tau, x, ell, dell):
    """``ell[ν] = ℓ_ν(x)``, ``dell[ν] = ℓ'_ν(x)`` on the nodes ``tau`` (products, no
    division by ``x − τ``)."""
    k = tau.shape[0]
    for nu in range(k):
        den = 1.0
        val = 1.0
        der = 0.0
        for mu in range(k):
            if mu == nu:
                continue
            den *= tau[nu] - tau[mu]
            # d/dx Π (x − τ_μ): product rule, accumulated alongside the product
            der = der * (x - tau[mu]) + val
            val *= x - tau[mu]
        ell[nu] = val / den
        dell[nu] = der / den


@hot_inline
def _state_at(ev, tabs, h, x, n):
    """``ev.qx, ev.vx`` = q(x), v(x) on the step polynomial held in ``ev.Q``."""
    s = tabs.tau.shape[0] - 1
    _basis(tabs.tau, x, ev.ell, ev.dell)
    for a in range(n):
        qa = 0.0
        va = 0.0
        for nu in range(s + 1):
            qa += ev.ell[nu] * ev.Q[nu, a]
            va += ev.dell[nu] * ev.Q[nu, a]
        ev.qx[a] = qa
        ev.vx[a] = va / h


@hot_inline
def _value(md, fn, t, q, v, out):
    md.prm[md.flags[F_TSLOT]] = t
    fn(ptr(q), ptr(v), ptr(md.prm), ptr(out))
    return out[0]


@hot
def event_values(md, ev, t, q, v):
    """``ev.g[e]`` = event ``e`` at the grid state ``(t, q, v)``."""
    for e in range(ev.count):
        ev.g[e] = _value(md, ev.fns[e], t, q, v, ev.scratch)


@hot
def room_for_crossings(ev):
    """Whether every event has room for one more crossing (a step adds at most one each)."""
    for e in range(ev.count):
        if ev.n[e] >= ev.t.shape[1]:
            return False
    return True


@hot
def after_step(md, tabs, h, tk, t1, k, qk, X, state, ev):
    """Book step ``k`` (from ``tk`` to ``t1``; ``qk`` its start, ``X`` its unknowns, state
    rows 0–2 its end): dense output, then the event crossings. Returns 0, or ``EVENT_TERMINAL`` when a
    terminal event reached its count (the step is still complete and booked)."""
    n = md.flags[F_N]
    s = tabs.tau.shape[0] - 1
    Q = ev.Q
    for a in range(n):
        Q[0, a] = qk[a]
    for nu in range(1, s + 1):
        for a in range(n):
            Q[nu, a] = qk[a] + X[(nu - 1) * n + a]
    if ev.dense.shape[0] > k:
        for nu in range(s + 1):
            for a in range(n):
                ev.dense[k, nu, a] = Q[nu, a]
    status = 0
    for e in range(ev.count):
        g0 = ev.g[e]
        g1 = _value(md, ev.fns[e], t1, state[0], state[2], ev.scratch)
        ev.g[e] = g1
        up = g0 < 0.0 and g1 >= 0.0
        down = g0 > 0.0 and g1 <= 0.0
        d = ev.direction[e]
        if not ((up and d >= 0) or (down and d <= 0)):
            continue
        j = ev.n[e]
        ev.n[e] = j + 1
        if ev.terminal[e] > 0 and j + 1 >= ev.terminal[e]:
            status = EVENT_TERMINAL
        if j >= ev.t.shape[1]:
            continue  # counted, not kept (a full record of an ensemble member)
        # Illinois on x ∈ [0, 1]: f(0) = g0, f(1) = g1 (the grid values)
        if g1 == 0.0:
            x = 1.0
        else:
            a0, fa, b0, fb = 0.0, g0, 1.0, g1
            side = 0
            x = 1.0
            xold = -1.0
            tiny = 4e-16 * max(1.0, abs(tk)) / h  # round-off of t, in units of the step
            for _ in range(_ILLINOIS_MAX):
                x = (a0 * fb - b0 * fa) / (fb - fa)
                if not (a0 < x < b0):
                    x = 0.5 * (a0 + b0)
                _state_at(ev, tabs, h, x, n)
                fx = _value(md, ev.fns[e], tk + x * h, ev.qx, ev.vx, ev.scratch)
                if fx != fx:
                    break  # undefined inside the step: keep the last estimate
                if fx == 0.0 or b0 - a0 <= tiny or abs(x - xold) <= tiny:
                    break
                xold = x
                if (fx > 0.0) == (fb > 0.0):
                    b0, fb = x, fx
                    if side == 1:
                        fa *= 0.5
                    side = 1
                else:
                    a0, fa = x, fx
                    if side == -1:
                        fb *= 0.5
                    side = -1
        if x == 1.0:
            ev.t[e, j] = t1
            for a in range(n):
                ev.q[e, j, a] = state[0, a]
                ev.v[e, j, a] = state[2, a]
        else:
            _state_at(ev, tabs, h, x, n)
            ev.t[e, j] = tk + x * h
            for a in range(n):
                ev.q[e, j, a] = ev.qx[a]
                ev.v[e, j, a] = ev.vx[a]
    return status
