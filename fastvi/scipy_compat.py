r"""SciPy's ``solve_ivp`` habits in :func:`fastvi.integrate`.

* ``t_span=(t0, t1)`` is accepted for ``t0=…, t_end=…``.
* ``t_end − t0`` need not be a whole number of steps: the run takes ``⌊(t_end − t0)/h⌋``
  steps of ``h`` and one shorter last step that lands on ``t_end``, as SciPy does. The
  one-step map with the shorter step is the same variational step (symplectic, the
  constraints held at its ends); only the modified energy of that one step differs.
* ``t_eval=`` returns the samples at those times, taken from the step polynomials (the
  dense output, :class:`fastvi.events.DenseSolution`) like SciPy's.
* A terminal event ends the result at the event: the last sample is the state at the
  event time, taken from the step polynomial (the record of the crossing).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from . import _validate as valid

__all__ = ["PiecewiseSolution"]

#: a span within this relative distance of a whole number of steps is that number of steps
_WHOLE = 1e-9


def span(t_span, t0: float, t_end, n_steps):
    """``(t0, t_end)`` from ``t_span=(t0, t1)``, refused when the start or the end is also
    given another way."""
    if t_span is None:
        return t0, t_end
    if t_end is not None or n_steps is not None:
        raise ValueError("give `t_span=(t0, t1)` or `t_end`/`n_steps`, not both "
                         f"(got t_span={t_span!r}, t_end={t_end!r}, n_steps={n_steps!r})")
    if t0 != 0.0:
        raise ValueError(f"give the start once: in `t_span=(t0, t1)` or as `t0`, not both "
                         f"(got t_span={t_span!r}, t0={t0!r})")
    try:
        a, b = t_span
    except (TypeError, ValueError):
        raise TypeError(f"`t_span` must be a pair (t0, t1) of floats, got {t_span!r}") from None
    a = valid.start_time(a)
    if isinstance(b, bool) or not isinstance(b, (int, float, np.integer, np.floating)) or not math.isfinite(b):
        raise ValueError(f"`t_span[1]` must be a finite float, got {b!r}")
    if not float(b) > a:
        raise ValueError(f"`t_span` must run forward, t_span[1] > t_span[0] (fastvi integrates "
                         f"forward in time), got {t_span!r}")
    return a, float(b)


def steps(h: float, t_end, n_steps, t0: float):
    """``(total, h, h_last)``: ``total`` steps of ``h``, then one of ``h_last`` (0: none).

    A span shorter than ``h`` is one step of the span. ``n_steps`` keeps its meaning.
    """
    if n_steps is not None or t_end is None:
        return valid.step_count(h, t_end, n_steps, t0), h, 0.0
    width = valid.end_time(t_end, t0) - t0
    k = round(width / h)
    if k >= 1 and abs(k * h - width) <= _WHOLE * width:
        return int(k), h, 0.0
    if width < h:
        return 1, width, 0.0
    k = math.floor(width / h)
    last = width - k * h
    if last <= _WHOLE * width:  # floor landed just above a whole number
        return int(k), h, 0.0
    return int(k), h, last


def eval_times(t_eval, t0: float, t_end: float | None):
    """``t_eval`` as a sorted finite float vector inside ``[t0, t_end]``."""
    if t_eval is None:
        return None
    try:
        te = np.asarray(t_eval, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"`t_eval` must be an array of times, got {type(t_eval).__name__}") from None
    if te.ndim != 1 or te.size == 0:
        raise ValueError(f"`t_eval` must be a non-empty 1-D array of times, got shape {te.shape}")
    if not np.all(np.isfinite(te)):
        raise ValueError("`t_eval` must be finite")
    if np.any(np.diff(te) < 0):
        raise ValueError("`t_eval` must be sorted increasingly (as in SciPy's solve_ivp)")
    hi = t_end if t_end is not None else np.inf
    slack = 1e-12 * max(1.0, abs(hi) if np.isfinite(hi) else 1.0)
    if te[0] < t0 - slack or te[-1] > hi + slack:
        raise ValueError(f"`t_eval` must lie within the integrated interval [{t0:g}, {hi:g}], got "
                         f"values from {te[0]:g} to {te[-1]:g}")
    return te


class PiecewiseSolution:
    """Dense output over consecutive pieces (the steps of ``h``, then the shorter last
    step): ``sol(t) -> (q, v)`` like :class:`fastvi.events.DenseSolution`."""

    def __init__(self, pieces):
        self.pieces = list(pieces)
        self.t_min, self.t_max = self.pieces[0].t_min, self.pieces[-1].t_max

    def __call__(self, t):
        tt = np.asarray(t, dtype=float)
        scalar = tt.ndim == 0
        tt = np.atleast_1d(tt)
        slack = 1e-12 * max(1.0, abs(self.t_max - self.t_min))
        if np.any(tt < self.t_min - slack) or np.any(tt > self.t_max + slack):
            raise ValueError(f"`t` must lie in the integrated interval [{self.t_min:g}, {self.t_max:g}], "
                             f"got values from {tt.min():g} to {tt.max():g}")
        n = self.pieces[0].points.shape[2]
        q, v = np.empty((tt.size, n)), np.empty((tt.size, n))
        # each time to the first piece whose end is at or after it
        ends = np.array([p.t_max for p in self.pieces[:-1]])
        which = np.searchsorted(ends, tt, side="left")
        for i, piece in enumerate(self.pieces):
            sel = which == i
            if sel.any():
                q[sel], v[sel] = piece(np.clip(tt[sel], piece.t_min, piece.t_max))
        return (q[0], v[0]) if scalar else (q, v)

    def __repr__(self) -> str:
        return f"PiecewiseSolution(t=[{self.t_min:g}, {self.t_max:g}], pieces={self.pieces!r})"


def _residuals(model, prm, t, q, v):
    """``(max|g|, max|G v + g_t|)`` at ``(t, q, v)``."""
    if model.m == 0:
        return 0.0, 0.0
    g = model.constraint_value(q, prm, t)
    gv = model.constraint_jacobian_value(q, prm, t) @ v + model.constraint_time_derivative_value(q, prm, t)
    return float(np.max(np.abs(g))), float(np.max(np.abs(gv)))


def _state_arrays(model, prm, t, q, v):
    """``p, H, max|g|, max|Gv + g_t|`` at the states ``(t_i, q_i, v_i)``."""
    K = t.shape[0]
    p, H, g, gv = np.empty_like(q), np.empty(K), np.empty(K), np.empty(K)
    for i in range(K):
        M = model.mass_matrix(q[i], prm)
        p[i] = M @ v[i]
        H[i] = 0.5 * v[i] @ p[i] + model.potential_energy(q[i], prm, float(t[i]))
        g[i], gv[i] = _residuals(model, prm, float(t[i]), q[i], v[i])
    return p, H, g, gv


def terminal_crossing(events, counts, times):
    """The crossing that ended a run: ``(t, e, j)``, crossing ``j`` of event ``e`` at time
    ``t``, the earliest over the terminal events whose count of crossings ``counts[e]``
    reached their ``terminal`` count; None if none did.

    ``times[e][j]`` is the located time of crossing ``j`` of event ``e`` (a single run's
    ``t_events``, or an ensemble member's rows of ``t_events``, which hold at least the
    ``terminal`` count of crossings)."""
    from .events import as_list, _terminal

    best = None
    for e, fn in enumerate(as_list(events)):
        count = _terminal(fn, e)
        if count and counts[e] >= count:
            te = float(times[e][count - 1])
            if best is None or te < best[0]:
                best = (te, e, count - 1)
    return best


def crossings_kept(times, t_event: float, e: int, j: int):
    """Per event, the boolean mask of the crossings ``times[k]`` that a run ended at
    crossing ``j`` of event ``e`` (at ``t_event``) keeps: those up to the event. Crossings
    later in the same last step did not happen (the run ended before them)."""
    keep = [np.asarray(ti) <= t_event for ti in times]
    keep[e] = np.arange(len(times[e])) <= j
    return keep


def state_at_event(model, prm, t_event: float, q, v):
    """``p, H, max|g|, max|Gv + g_t|`` at the event state ``(t_event, q, v)``."""
    p, H, g, gv = _state_arrays(model, prm, np.array([t_event]), q[None], v[None])
    return p[0], H[0], g[0], gv[0]


def work_at_event(w_prev, w_step, t_prev: float, t_step: float, t_event: float):
    """The work at ``t_event``, interpolated linearly between the last two samples
    ``(t_prev, w_prev)`` and ``(t_step, w_step)`` (the work is known at step ends only)."""
    frac = (t_event - t_prev) / (t_step - t_prev) if t_step > t_prev else 1.0
    return w_prev + frac * (w_step - w_prev)


def end_at_event(result, model, prm, events):
    """A result ended by a terminal event, with its last sample moved to the event: the
    state at the event time from the step polynomial (``sol(t_event)`` with dense output,
    else the crossing's record, the same polynomial). Crossings after it, in the same last
    step, are dropped. The work there (a forced or driven model) is interpolated linearly
    between the last two samples (the ends of the step with ``save_every=1``).

    :func:`fastvi.integrate_ensemble` ends its terminated members by the same helpers
    (:func:`terminal_crossing`, :func:`crossings_kept`, :func:`state_at_event`,
    :func:`work_at_event`)."""
    from .status import Status

    if result.status != Status.TERMINATED or not result.t_events:
        return result
    best = terminal_crossing(events, [len(x) for x in result.t_events], result.t_events)
    if best is None:
        return result
    te, e, j = best
    if result.sol:
        qe, ve = result.sol(te)
        result.sol.t_max = te
    else:
        qe, ve = result.q_events[e][j].copy(), result.v_events[e][j].copy()
    keep = crossings_kept(result.t_events, te, e, j)
    t_prev, t_step = float(result.t[-2]), float(result.t[-1])
    t, q, v = result.t.copy(), result.q.copy(), result.v.copy()
    p, H = result.p.copy(), result.energy.copy()
    g, gv = result.constraint_residual.copy(), result.velocity_residual.copy()
    t[-1], q[-1], v[-1] = te, qe, ve
    p[-1], H[-1], g[-1], gv[-1] = state_at_event(model, prm, te, q[-1], v[-1])
    extra = {}
    for name in ("work", "work_forces"):
        if getattr(result, name) is not None:
            w = getattr(result, name).copy()
            w[-1] = work_at_event(w[-2], w[-1], t_prev, t_step, te)
            extra[name] = w
    return replace(result, t=t, q=q, v=v, p=p, energy=H, constraint_residual=g, velocity_residual=gv,
                   t_events=[x[k] for x, k in zip(result.t_events, keep)],
                   q_events=[x[k] for x, k in zip(result.q_events, keep)],
                   v_events=[x[k] for x, k in zip(result.v_events, keep)], **extra)


def append_last_step(result, tail, h_last: float, t_end: float):
    """``result`` followed by the one-step run ``tail`` (the shorter last step), whose end
    is ``t_end`` exactly (``t0 + k h + h_last`` may round to a neighbour)."""
    from .status import Status

    cat = lambda a, b: np.concatenate([a, b[1:]])  # noqa: E731 - the tail's first sample is ours
    arrays = {name: cat(getattr(result, name), getattr(tail, name)) for name in
              ("t", "q", "v", "p", "energy", "constraint_residual", "velocity_residual",
               "newton_iterations")}
    if tail.success:
        arrays["t"][-1] = t_end
    for name in ("work", "work_forces"):
        if getattr(result, name) is not None:
            arrays[name] = cat(getattr(result, name), getattr(tail, name) + getattr(result, name)[-1])
    extra = {}
    if result.t_events is not None:
        extra = {k: [np.concatenate([a, b]) for a, b in zip(getattr(result, k), getattr(tail, k))]
                 for k in ("t_events", "q_events", "v_events")}
    if result.sol:
        extra["sol"] = PiecewiseSolution([result.sol, tail.sol])
    st, ts = result.stats, tail.stats
    stats = dict(st, steps=st["steps"] + ts["steps"],
                 newton_iterations=st["newton_iterations"] + ts["newton_iterations"],
                 max_residual=max(st["max_residual"], ts["max_residual"]),
                 full_newton_steps=st["full_newton_steps"] + ts["full_newton_steps"],
                 integration_time=st["integration_time"] + ts["integration_time"],
                 wall_time=st["wall_time"] + ts["wall_time"], last_step=h_last)
    status = tail.status
    failed = None if status >= 0 else st["steps"]
    return replace(result, **arrays, **extra, stats=stats, status=Status(int(status)),
                   failed_step=failed)


def resample(result, model, prm, t_eval):
    """The result at the times ``t_eval`` (those up to its last sample), from its dense
    output: ``q, v`` from the step polynomials, ``p = M(q) v``, the energy and the
    residuals evaluated there, the work (forced or driven models) interpolated linearly
    between the grid samples and counted from the first time (the energy error and balance
    refer to the first sample, as always), and the Newton iterations of the steps since the
    previous time."""
    te = t_eval[t_eval <= result.t[-1] + 1e-12 * max(1.0, abs(result.t[-1]))]
    q, v = result.sol(te)
    q, v = np.atleast_2d(q), np.atleast_2d(v)
    p, H, g, gv = _state_arrays(model, prm, te, q, v)
    cum = np.concatenate([[0.0], np.cumsum(result.newton_iterations[1:])])
    at = np.searchsorted(result.t, te, side="right") - 1
    iters = np.diff(np.concatenate([[0.0], cum[np.clip(at, 0, cum.size - 1)]]))
    extra = {}
    for name in ("work", "work_forces"):  # from the first sample, like the energy error
        if getattr(result, name) is not None:
            w = np.interp(te, result.t, getattr(result, name))
            extra[name] = w - w[0]
    return replace(result, t=te, q=q, v=v, p=p, energy=H, constraint_residual=g,
                   velocity_residual=gv, newton_iterations=iters, **extra)
