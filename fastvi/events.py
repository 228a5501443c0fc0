r"""Events and dense output of :func:`fastvi.integrate` (SciPy's ``solve_ivp`` conventions).

An event is a function ``event(t, q, v, params) -> float`` in numba's nopython subset; a
zero crossing is located on the step polynomial inside the compiled time loop
(:mod:`fastvi.kernels.events`). Optional attributes, as in SciPy:

``terminal`` : bool or int, default False
    True (or 1): the run ends at the first crossing (its last sample is the state at the
    crossing, as in SciPy); an integer ``k > 1``: at the k-th crossing.
``direction`` : float, default 0
    Count only crossings from negative to positive (``> 0``), positive to negative
    (``< 0``), or both (``0``).

Each event is compiled once, like the model's callbacks, into a ``numba.cfunc`` of the one
callback signature (the time travels in the hidden last entry of the parameters).

Dense output keeps each step's ``s + 1`` control points: ``8 (s+1) n`` bytes a step
(96 bytes for ``P2L-Q3G`` on the double pendulum), and :class:`DenseSolution` evaluates the
step polynomial between the grid points.
"""

from __future__ import annotations

import numbers
import warnings

import numba as nb
import numpy as np

from .kernels.layout import EVENT_SLOTS, Events
from .tables import lagrange_basis

#: the public name; ``prepare``, ``grow`` and ``collect`` serve :func:`fastvi.integrate`
__all__ = ["DenseSolution"]

_INITIAL_CAPACITY = 64


class DenseSolution:
    r"""The trajectory between the grid points: ``q(t)`` and ``v(t)`` from the step polynomials.

    On step ``k`` (``t_k = t0 + k h``, ``τ = (t − t_k)/h``)
    ``q(t) = Σ_ν Q_k^ν ℓ_ν(τ)`` and ``v(t) = (1/h) Σ_ν Q_k^ν ℓ'_ν(τ)`` with the step's control
    points ``Q_k^ν`` (``Q_k^0 = q_k``, ``Q_k^s = q_{k+1}``). At the grid points ``q`` is the
    integrator's ``q_k`` (order ``2s``); between them the interpolant is less accurate: the
    measured orders are in ``docs/events.md`` (order ``s + 1`` for ``q`` and ``s`` for ``v``
    inside a step). ``v`` at a grid point is the polynomial's, not the projected
    ``Result.v``.

    Parameters
    ----------
    t0, h : float
        Start time and step.
    tau : ndarray (s+1,)
        The control nodes of the method on [0, 1].
    points : ndarray (steps, s+1, n)
        The control points of every step.
    """

    def __init__(self, t0: float, h: float, tau: np.ndarray, points: np.ndarray):
        self.t0, self.h = float(t0), float(h)
        self.tau = np.asarray(tau, dtype=float)
        self.points = points
        self.t_min, self.t_max = self.t0, self.t0 + self.h * points.shape[0]

    def __call__(self, t):
        """``(q, v)`` at the time(s) ``t``.

        Parameters
        ----------
        t : float or array_like (T,)
            Times in ``[t0, t0 + steps h]``.

        Returns
        -------
        q, v : ndarray
            Shape ``(n,)`` each for a scalar ``t``, ``(T, n)`` (one row per time, like
            :attr:`fastvi.Result.q`) for an array.

        Raises
        ------
        ValueError
            A time outside the integrated interval.
        """
        tt = np.asarray(t, dtype=float)
        scalar = tt.ndim == 0
        tt = np.atleast_1d(tt)
        span = self.t_max - self.t_min
        if np.any(tt < self.t_min - 1e-12 * max(1.0, abs(span))) or np.any(tt > self.t_max + 1e-12 * max(1.0, abs(span))):
            raise ValueError(f"`t` must lie in the integrated interval [{self.t_min:g}, {self.t_max:g}], "
                             f"got values from {tt.min():g} to {tt.max():g}")
        steps = self.points.shape[0]
        k = np.clip(np.floor((tt - self.t0) / self.h).astype(np.int64), 0, steps - 1)
        # a grid time t0 + k h must land on step k at x = 0 (exactly q_k), whatever the
        # rounding of (t − t0)/h
        nxt = (tt >= self.t0 + (k + 1) * self.h) & (k < steps - 1)
        k = k + nxt
        x = np.clip((tt - (self.t0 + k * self.h)) / self.h, 0.0, 1.0)
        x[tt >= self.t0 + steps * self.h] = 1.0  # the last grid point: exactly q at its end
        ell, dell = lagrange_basis(self.tau, x)  # (s+1, T)
        P = self.points[k]  # (T, s+1, n)
        q = np.einsum("vt,tvn->tn", ell, P)
        v = np.einsum("vt,tvn->tn", dell, P) / self.h
        return (q[0], v[0]) if scalar else (q, v)

    def __repr__(self) -> str:
        return (f"DenseSolution(t=[{self.t_min:g}, {self.t_max:g}], steps={self.points.shape[0]}, "
                f"n={self.points.shape[2]}, {self.points.nbytes / max(1, self.points.shape[0]):.0f} bytes/step)")


def as_list(events):
    if events is None:
        return []
    if callable(events):
        return [events]
    try:
        fns = list(events)
    except TypeError:
        raise TypeError(f"`events` must be a function or a list of functions, got {events!r}") from None
    for i, fn in enumerate(fns):
        if not callable(fn):
            raise TypeError(f"`events[{i}]` must be a function event(t, q, v, params) -> float, got {fn!r}")
    return fns


def check_list(events) -> None:
    """Refuse a bad ``events`` argument (not a function or list of them, or too many, or a
    bad ``terminal``/``direction``) before anything is compiled or sent anywhere."""
    fns = as_list(events)
    if len(fns) > EVENT_SLOTS:
        raise ValueError(f"`events` may hold at most {EVENT_SLOTS} functions, got {len(fns)}")
    for i, fn in enumerate(fns):
        _terminal(fn, i)
        _direction(fn, i)


def _terminal(fn, i) -> int:
    value = getattr(fn, "terminal", False)
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, numbers.Integral) and value >= 0:
        return int(value)
    raise ValueError(f"`events[{i}].terminal` must be a bool or a non-negative int, got {value!r}")


def _direction(fn, i) -> int:
    value = getattr(fn, "direction", 0)
    if not isinstance(value, numbers.Real) or not np.isfinite(value):
        raise ValueError(f"`events[{i}].direction` must be a number (−1, 0 or +1), got {value!r}")
    return int(np.sign(value))


def prepare(model, method, events, dense_steps: int, capacity: int = _INITIAL_CAPACITY):
    """The :class:`~fastvi.kernels.layout.Events` of a run (with ``count = 0`` and no dense
    rows when there is nothing to watch: the time loop then skips it). ``dense_steps`` rows
    of control points are kept (0: no dense output), and room for ``capacity`` crossings
    per event."""
    from .model import _absent, _wrap

    check_list(events)
    fns = as_list(events)
    k = model.params.shape[0]
    compiled = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", nb.NumbaExperimentalFeatureWarning)
        for i, fn in enumerate(fns):
            try:
                compiled.append(_wrap("event@t", fn, model.n, model.m, k))
            except TypeError as exc:
                raise TypeError(str(exc).replace("callback `event`", f"event function `events[{i}]`"), ) from None
    term = np.array([_terminal(f, i) for i, f in enumerate(fns)] + [0] * (EVENT_SLOTS - len(fns)), dtype=np.int64)
    dirs = np.array([_direction(f, i) for i, f in enumerate(fns)] + [0] * (EVENT_SLOTS - len(fns)), dtype=np.int64)
    cbs = tuple(compiled) + (_absent,) * (EVENT_SLOTS - len(compiled))
    n, s = model.n, method.s
    E = max(1, len(fns))
    cap = capacity if fns else 1
    return Events(cbs, len(fns), dirs, term, np.zeros(EVENT_SLOTS), np.full((E, cap), np.nan),
                  np.full((E, cap, n), np.nan), np.full((E, cap, n), np.nan),
                  np.zeros(EVENT_SLOTS, dtype=np.int64), np.zeros((dense_steps, s + 1, n)),
                  np.zeros((s + 1, n)), np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(s + 1),
                  np.zeros(s + 1), np.zeros(1))


def grow(ev):
    """The same records with twice the room."""
    E, cap = ev.t.shape
    t = np.full((E, 2 * cap), np.nan)
    q = np.full((E, 2 * cap, ev.q.shape[2]), np.nan)
    v = np.full_like(q, np.nan)
    t[:, :cap], q[:, :cap], v[:, :cap] = ev.t, ev.q, ev.v
    return ev._replace(t=t, q=q, v=v)


def collect(ev):
    """``(t_events, q_events, v_events)``: one array per event, as in SciPy."""
    out_t, out_q, out_v = [], [], []
    for e in range(ev.count):
        j = int(ev.n[e])
        out_t.append(ev.t[e, :j].copy())
        out_q.append(ev.q[e, :j].copy())
        out_v.append(ev.v[e, :j].copy())
    return out_t, out_q, out_v
